"""``blurtrap calibrate/diagnose MANIFEST --report DIR``, run in-process through
``blurtrap.cli.main`` on a small simulated manifest (2048 frames)."""

import json
import re
import types

import numpy as np
import pytest

from blurtrap.cli import main


@pytest.fixture(scope="module")
def manifest(tmp_path_factory):
    """One camera recording with a large tracking error (10 nm rms against a 20 nm trap
    rms): the ``blur`` model misses ``tracking_noise`` clearly even in 2048 frames."""
    out = tmp_path_factory.mktemp("cli_report") / "sim"
    assert main(["simulate", "--k", "0.01", "--radius", "0.765", "--exposure-ms", "0.5",
                 "--fps", "1500", "--frames", "2048", "--tracking-nm", "10", "--seed", "0",
                 "--out", str(out), "--json"]) == 0
    return out / "manifest.json"


def _image_ok(path):
    """A PNG that matplotlib reads back as a picture of reasonable size."""
    from matplotlib.image import imread

    img = imread(path)
    assert img.ndim == 3 and img.shape[2] in (3, 4), (path, img.shape)
    assert img.shape[0] > 200 and img.shape[1] > 300, (path, img.shape)
    assert float(np.ptp(img[..., :3])) > 0.5, f"{path} is blank"


def _table_value(report: str, label: str) -> str:
    """The value cell of the parameter-table row whose first cell starts with `label`."""
    m = re.search(rf"^\| {re.escape(label)}[^|]*\| ([^|]+) \|", report, flags=re.M)
    assert m, f"no row {label!r} in report.md:\n{report}"
    return m.group(1).strip()


def test_calibrate_report(manifest, tmp_path, capsys):
    out = tmp_path / "new" / "report"  # parents created
    capsys.readouterr()
    assert main(["calibrate", str(manifest), "--method", "psd", "--report", str(out),
                 "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    files = ["report.md", "result.json", "spectrum_0.png", "histogram_0.png"]
    assert res["report"]["files"] == files and res["report"]["failed"] == []
    assert sorted(p.name for p in out.iterdir()) == sorted(files)
    for f in files[2:]:
        _image_ok(out / f)
    report = (out / "report.md").read_text()
    for f in files[2:]:
        assert f"]({f})" in report
    # k in pN/nm equal, to the printed precision, to the JSON result
    assert _table_value(report, "k (stiffness)") == f"{res['k'] * 1e3:.6g}"
    assert _table_value(report, "gamma (friction)") == f"{res['gamma'] * 1e6:.6g}"
    assert _table_value(report, "D = kT/gamma") == f"{res['diffusion'] * 1e12:.6g}"
    assert _table_value(report, "f_c = k/(2 pi gamma)") == f"{res['corner_frequency']:.6g}"
    eps_nm = float(_table_value(report, "eps (tracking error rms)"))
    assert eps_nm == pytest.approx(np.sqrt(res["tracking_var"]) * 1e9, rel=1e-5)
    for unit in ("| pN/nm |", "| pN s/um |", "| um^2/s |", "| nm |", "| Hz |"):
        assert unit in report
    assert f"p = {res['gof']['p_value']:.3g}" in report
    assert json.loads((out / "result.json").read_text())["k"] == res["k"]


def test_report_replaces_only_its_own_files(manifest, tmp_path, capsys):
    """A report into a DIR with files replaces report.md and leaves the user's other files
    alone; without --json the table is printed with the report's path. A method without
    friction (equipartition) gets the data spectrum and says why there is no model."""
    out = tmp_path / "rep"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "report.md").write_text("stale")
    capsys.readouterr()
    assert main(["calibrate", str(manifest), "--method", "equipartition", "--report",
                 str(out)]) == 0
    text = capsys.readouterr().out
    assert "pN/nm" in text and f"report: {out / 'report.md'} (3 files)" in text
    assert (out / "notes.txt").read_text() == "mine"
    report = (out / "report.md").read_text()
    assert report.startswith("# blurtrap calibration report") and "Method `equipartition`" in report
    _image_ok(out / "spectrum_0.png")
    assert "data only: method equipartition fits no friction" in report
    assert "- histogram_0.png: method equipartition fits no friction" in report
    assert not (out / "histogram_0.png").exists()


def test_report_dir_that_is_a_file_is_refused_before_fitting(manifest, tmp_path, capsys,
                                                             monkeypatch):
    import blurtrap.diagnostics
    import blurtrap.inference

    def boom(*a, **kw):
        raise AssertionError("fitted before the report folder was checked")

    monkeypatch.setattr(blurtrap.inference, "calibrate", boom)
    monkeypatch.setattr(blurtrap.diagnostics, "diagnose", boom)
    target = tmp_path / "taken"
    target.write_text("a file")
    for command in ("calibrate", "diagnose"):
        capsys.readouterr()
        assert main([command, str(manifest), "--report", str(target)]) == 1
        err = capsys.readouterr().err
        assert err.startswith(f"blurtrap {command}: error: --report {target}: is a file")
        assert target.read_text() == "a file"


def test_help_says_what_report_overwrites(capsys):
    for command in ("calibrate", "diagnose"):
        assert main([command, "--help"]) == 0
        text = " ".join(capsys.readouterr().out.split())
        assert "--report DIR" in text and "overwritten" in text and "left alone" in text


def test_diagnose_report_names_the_missing_effect(manifest, tmp_path, capsys):
    out = tmp_path / "diag"
    capsys.readouterr()
    assert main(["diagnose", str(manifest), "--model", "blur", "--report", str(out),
                 "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    top = d["ranking"][0]
    assert top["effect"] == "tracking_noise" and top["significant"] is True
    figures = ["ranking.png", "before_after.png", "spectrum_0.png", "histogram_0.png"]
    assert d["report"]["files"] == ["report.md", "diagnosis.json"] + figures
    for f in figures:
        _image_ok(out / f)
    report = (out / "report.md").read_text()
    assert "**NOT adequate**" in report
    assert "Missing effect: **`tracking_noise`**" in report
    assert re.search(r"^\| 1 \| `tracking_noise` \|", report, flags=re.M)
    assert "## Refit with `tracking_noise` added" in report
    # before -> after of k, in lab units, with the change in the refit's standard errors
    m = re.search(r"^\| k \| ([^|]+) \| ([^|]+) \| pN/nm \| ([^|]+) \|", report, flags=re.M)
    assert m, report
    before_k, after_k = (float(v) for v in m.groups()[:2])
    assert before_k == pytest.approx(d["fit"]["k"] * 1e3, rel=1e-5)
    assert after_k > before_k  # white noise read as trap motion made k too small
    refit = report.split("## Refit with")[1].split("## Fit of the model")[0]
    k_se = float(re.search(r"^\| k \(stiffness\) \| [^|]+ \| ([^|]+) \|", refit,
                           flags=re.M).group(1))
    assert abs(after_k - 0.01) < 3 * k_se  # the simulated k, within 3 SE of the refit
    # the base fit's k, to the printed precision, and the refit's eps row
    base_k = d["fit"]["k"] * 1e3
    assert f"| k (stiffness) | {base_k:.6g} |" in report
    assert "eps (tracking error rms)" in report.split("## Fit of the model")[0]
    for f in figures:
        assert f"]({f})" in report
    # add and refit from the command line: the text output also gives the refit
    assert main(["diagnose", str(manifest), "--model", "blur"]) == 0
    text = capsys.readouterr().out
    after = text.split("fit with tracking_noise added (model blur+tracking_noise):")[1]
    assert re.search(r"^  k +\d", after, flags=re.M) and "eps (tracking rms)" in after


def test_volts_recording_is_drawn_in_metres():
    from blurtrap._report_figures import in_metres
    from blurtrap.data import Recording

    rec = Recording(np.linspace(-1.0, 1.0, 64), frame_interval=1e-3, exposure=1e-3,
                    position_unit="V")
    fit = types.SimpleNamespace(params={"displacement_sensitivity": 2e-7})
    m = in_metres(rec, fit)
    assert m.position_unit == "m"
    np.testing.assert_allclose(m.positions, rec.positions * 2e-7, rtol=1e-15)
    with pytest.raises(ValueError, match="displacement_sensitivity"):
        in_metres(rec, types.SimpleNamespace(params={}))


def _result(names, values, errors, k_rec, k_err, model="standard"):
    from blurtrap.inference import CalibrationResult

    return CalibrationResult(
        method="likelihood", model=model, param_names=tuple(names),
        values=np.asarray(values, float), covariance=np.diag(np.asarray(errors, float) ** 2),
        temperature=295.0, k_per_recording=np.asarray(k_rec, float),
        k_per_recording_err=np.asarray(k_err, float), gof={}, n_recordings=len(k_rec),
        n_frames=1000)


def test_parameter_table_in_lab_units_for_volts():
    """k, gamma, D, eps, f_c, Rd and Rf rows in lab units, checked against the SI values
    converted here (D = kT/gamma, f_c = k/(2 pi gamma), Rf = k Rd)."""
    from blurtrap._report import parameter_table

    k, g, tv, rd = 3e-5, 1.75e-8, 4e-18, 80e-9  # N/m, N s/m, m^2, m/V
    fit = _result(["k", "gamma", "tracking_var", "displacement_sensitivity",
                   "force_sensitivity"], [k, g, tv, rd, k * rd],
                  [1e-6, 1e-10, 1e-18, 1e-9, 5e-14], [k], [1e-6], model="photodiode_aa")
    table = "\n".join(parameter_table(fit))
    kt = 1.380649e-23 * 295.0
    expect = {"k (stiffness)": (k * 1e3, "pN/nm"), "gamma (friction)": (g * 1e6, "pN s/um"),
              "D = kT/gamma": (kt / g * 1e12, "um^2/s"),
              "eps (tracking error rms)": (2.0, "nm"),
              "f_c = k/(2 pi gamma)": (k / (2 * np.pi * g), "Hz"),
              "Rd (displacement sensitivity)": (80.0, "nm/V"),
              "Rf = k Rd (force sensitivity)": (k * rd * 1e12, "pN/V")}
    for label, (value, unit) in expect.items():
        m = re.search(rf"^\| {re.escape(label)}[^|]*\| ([^|]+) \| [^|]+ \| ([^|]+) \|", table,
                      flags=re.M)
        assert m, f"no row {label!r}:\n{table}"
        assert float(m.group(1)) == pytest.approx(value, rel=1e-5), label
        assert m.group(2).strip() == unit, label
    # eps error from eps^2's by the delta method: 1 nm^2 / (2 x 2 nm)
    assert "| eps (tracking error rms) | 2 | 0.25 | nm |" in table


def test_per_recording_table_when_k_differs():
    from blurtrap._report import per_recording_table
    from blurtrap.data import Recording

    g = 1e-8
    fit = _result(["k[P=100 mW]", "k[P=200 mW]", "gamma"], [1e-5, 2e-5, g],
                  [1e-7, 2e-7, 1e-10], [1e-5, 2e-5], [1e-7, 2e-7])
    recs = [Recording(np.linspace(-1e-8, 1e-8, 8), frame_interval=1e-3, exposure=1e-3, name=f"r{i}")
            for i in range(2)]
    rows = per_recording_table(fit, recs)[2:]
    assert rows[0].startswith("| recording 0 (r0) | 0.01 | 0.0001 | ")
    assert rows[1].startswith("| recording 1 (r1) | 0.02 | 0.0002 | ")
    assert float(rows[1].split("|")[4]) == pytest.approx(2e-5 / (2 * np.pi * g), rel=1e-5)
    assert per_recording_table(_result(["k", "gamma"], [1e-5, g], [1e-7, 1e-10], [1e-5],
                                       [1e-7]), recs[:1]) == []


def test_anti_aliased_photodiode_fit_is_drawn(tmp_path):
    """calibrate names the anti-aliased photodiode model ``photodiode_aa``: the name
    resolves (no blur, no folding), its drawn spectrum is the unfolded Lorentzian plus the
    white floor eps^2 dt (numpy reference), and a volts trace is drawn in nm."""
    from blurtrap._report_figures import Figures, in_metres, spectrum_figure
    from blurtrap.data import Recording
    from blurtrap.inference import get_model
    from blurtrap.plotting._common import model_psd

    mdl = get_model("photodiode_aa")
    assert (mdl.blur, mdl.alias, mdl.noise) == (False, False, True)
    k, g, tv, rd, dt = 3e-5, 1.75e-8, 4e-18, 80e-9, 5e-5
    fit = _result(["k", "gamma", "tracking_var", "displacement_sensitivity",
                   "force_sensitivity"], [k, g, tv, rd, k * rd],
                  [1e-6, 1e-10, 1e-18, 1e-9, 5e-14], [k], [1e-6], model="photodiode_aa")
    x = np.random.default_rng(5).normal(0.0, 1.0, 4096) * np.sqrt(1.380649e-23 * 295 / k) / rd
    rec = Recording(x, frame_interval=dt, exposure=dt, position_unit="V")
    f = np.array([10.0, 300.0, 3000.0, 9000.0])
    tau, s2 = g / k, 1.380649e-23 * 295.0 / k
    ref = 2 * s2 * tau / (1 + (2 * np.pi * f * tau) ** 2) + tv * dt
    np.testing.assert_allclose(model_psd(fit, in_metres(rec, fit), f), ref, rtol=1e-10)
    figs = Figures(tmp_path)
    figs.attempt("spectrum_0", lambda: spectrum_figure(in_metres(rec, fit), fit, "r"), "c")
    assert figs.failed == [] and figs.files == ["spectrum_0.png"]
    _image_ok(tmp_path / "spectrum_0.png")


def test_failed_figure_is_reported_and_exits_nonzero(manifest, tmp_path, capsys, monkeypatch):
    """A figure that raises leaves the rest of the report, is listed in report.md and on
    stderr, and the command exits 1 (the report is incomplete)."""
    import blurtrap._report_figures as rf

    def broken(*a, **kw):
        raise RuntimeError("no spectrum today")

    monkeypatch.setattr(rf, "spectrum_figure", broken)
    out = tmp_path / "rep"
    capsys.readouterr()
    assert main(["calibrate", str(manifest), "--method", "equipartition", "--report",
                 str(out)]) == 1
    cap = capsys.readouterr()
    assert "warning: report figure spectrum_0.png: RuntimeError: no spectrum today" in cap.err
    report = (out / "report.md").read_text()
    assert "**Figures that failed:**" in report and "no spectrum today" in report
    assert "| k (stiffness) |" in report and not (out / "spectrum_0.png").exists()


def test_posterior_goes_into_the_report(manifest, tmp_path):
    """calibrate --posterior --report: the posterior's summary in report.md, its dict in
    result.json (a stand-in posterior: the sampler itself is tested elsewhere)."""
    from blurtrap._report import write_calibration_report

    class FakePosterior:
        def summary(self):
            return "posterior: k median 0.01 pN/nm"

        def to_dict(self):
            return {"method": "posterior", "k": 1e-5}

    k, g = 1e-5, 1.37e-8
    fit = _result(["k", "gamma"], [k, g], [1e-7, 1e-10], [k], [1e-7])
    info = write_calibration_report(tmp_path, fit, str(manifest), posterior=FakePosterior())
    report = (tmp_path / "report.md").read_text()
    assert "## Posterior (emcee)" in report and "posterior: k median 0.01 pN/nm" in report
    assert json.loads((tmp_path / "result.json").read_text())["posterior"]["k"] == 1e-5
    assert info["failed"] == [] and "spectrum_0.png" in info["files"]


def test_recordings_table_says_the_unit_the_positions_were_read_from():
    """A manifest in nm is loaded into metres: the table said "m" where the user's file holds
    nm; it now says both."""
    import numpy as np

    import blurtrap as bt
    from blurtrap._report import recordings_table

    y = np.random.default_rng(0).standard_normal(4096) * 1e-8
    nm = bt.Recording(y, frame_interval=1e-3, exposure=1e-3, metadata={"position_unit": "nm"})
    plain = bt.Recording(y, frame_interval=1e-3, exposure=1e-3)
    rows = recordings_table([nm, plain])
    assert rows[0].endswith("| positions |")
    assert rows[2].endswith("| m (read from nm) |") and rows[3].endswith("| m |")
