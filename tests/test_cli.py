"""The `blurtrap` command line, run in-process through `blurtrap.cli.main` (plus one
subprocess for the installed entry point)."""

import json
import math
import os
import pathlib
import re
import subprocess
import sys

import pytest

from blurtrap.cli import main

KT = 1.380649e-23 * 295.0


def test_help_subprocess():
    exe = pathlib.Path(sys.executable).with_name("blurtrap")
    cmd = [str(exe), "--help"] if exe.exists() else [sys.executable, "-m", "blurtrap.cli",
                                                       "--help"]
    env = dict(os.environ, MPLBACKEND="Agg")
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    for command in ("demo", "simulate", "calibrate", "diagnose"):
        assert command in out.stdout


@pytest.mark.parametrize("command, flag", [("demo", "--quick"), ("simulate", "--exposure-ms"),
                                           ("calibrate", "--method"), ("diagnose", "--add"),
                                           ("calibrate", "--posterior")])
def test_every_command_has_help(command, flag, capsys):
    assert main([command, "--help"]) == 0
    assert flag in capsys.readouterr().out


def test_demo_quick(tmp_path, capsys):
    out = tmp_path / "demo"
    rc = main(["demo", "--quick", "--json", "--out", str(out)])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert cap.err == ""  # --json is quiet
    summary = json.loads(cap.out)
    assert summary["ok"] is True
    report = (out / "report.md").read_text()
    assert json.loads((out / "results.json").read_text())["ok"] is True
    for name in ("fig1a_universal_curve", "fig1b_histogram", "fig3_fractional_variance",
                 "fig4_stiffness_vs_power", "fig5_highpass", "fig6_psd", "fig7_deviation",
                 "naive_error_map"):
        assert (out / f"{name}.png").stat().st_size > 5000, name
        assert f"]({name}.png)" in report
    assert "pN/nm" in report and "pN s/um" in report
    rows = {r["label"]: r for r in summary["results"]}
    # naive equipartition over-estimates k at 2 ms, the more the stiffer the trap
    naive = rows["naive equipartition, W = 2 ms"]["k_error_pct"]
    assert naive[0] > 10 and naive[-1] > 60 and naive == sorted(naive)
    # the joint blur-corrected fit recovers k and gamma
    joint = rows["variance vs exposure, joint"]
    assert max(abs(e) for e in joint["k_error_pct"]) < 5
    assert abs(joint["gamma_error_pct"]) < 10
    steps = {s["step"]: s["status"] for s in summary["steps"]}
    assert steps["exact likelihood"] == "skipped"
    assert "failed" not in steps.values()


def _tiny_demo_config(demo_mod):
    """The quick demo's sizes (its compiled simulator and fits are reused), fewer steps."""
    import dataclasses

    return dataclasses.replace(demo_mod.quick_config(), exact_likelihood=False, posterior=True,
                               psd_models=(), per_power_variance=False, power_exposures=())


def test_demo_table_progress_and_posterior(tmp_path, capsys, monkeypatch):
    """Without --json: progress on stderr, the lab-unit table on stdout; a posterior is used
    when `blurtrap.inference.sample_posterior` exists (tiny config, stand-in sampler)."""
    import numpy as np

    import blurtrap._demo as demo_mod
    import blurtrap.inference as inference

    calls = {}

    class FakePosterior:
        def __init__(self, samples):
            self.samples = samples

    def fake_sample_posterior(data, *, n_steps=2000, n_walkers=32, seed=0, progress=False):
        calls.update(n_steps=n_steps, n_walkers=n_walkers, seed=seed)
        rng = np.random.default_rng(seed)
        return FakePosterior({"k": 1e-5 * (1 + 0.01 * rng.standard_normal(400)),
                              "gamma": 2.74e-8 * (1 + 0.02 * rng.standard_normal(400))})

    monkeypatch.setattr(inference, "sample_posterior", fake_sample_posterior, raising=False)
    tiny = _tiny_demo_config(demo_mod)
    monkeypatch.setattr(demo_mod, "quick_config", lambda seed=0: tiny)
    rc = main(["demo", "--quick", "--out", str(tmp_path)])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert "simulate exposure series" in cap.err and "done" in cap.err
    assert "k @ 100 mW [pN/nm]" in cap.out and "gamma [pN s/um]" in cap.out
    assert "truth" in cap.out and "%" in cap.out
    assert calls == {"n_steps": tiny.posterior_steps, "n_walkers": 16, "seed": 0}
    assert "posterior median" in cap.out
    assert (tmp_path / "corner.png").exists()


def test_demo_without_posterior_says_so(tmp_path, capsys, monkeypatch):
    import blurtrap._demo as demo_mod
    import blurtrap.inference as inference

    monkeypatch.delattr(inference, "sample_posterior", raising=False)
    tiny = _tiny_demo_config(demo_mod)
    summary = demo_mod.demo(tmp_path, quiet=True, config=tiny)
    assert summary["posterior"] == "posterior: not available in this version"
    assert "posterior: not available in this version" in (tmp_path / "report.md").read_text()


def test_simulate_calibrate_round_trip(tmp_path, capsys):
    out = tmp_path / "sim"
    rc = main(["simulate", "--k", "0.02", "0.04", "--radius", "1.53", "--exposure-ms", "0.5",
               "--fps", "1500", "--frames", "8192", "--tracking-nm", "2", "--power-mw", "200",
               "400", "--seed", "1", "--out", str(out), "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    info = json.loads(cap.out)
    manifest = out / "manifest.json"
    assert info["manifest"] == str(manifest) and info["n_recordings"] == 2
    doc = json.loads(manifest.read_text())
    assert [r["laser_power_mW"] for r in doc["recordings"]] == [200, 400]
    assert doc["recordings"][0]["exposure_s"] == pytest.approx(5e-4)
    assert all((out / r["file"]).exists() for r in doc["recordings"])

    gamma = 6 * math.pi * 0.00095 * 1.53e-6
    d_um2 = KT / gamma * 1e12
    # blur-corrected equipartition with the known D: readable table in lab units
    rc = main(["calibrate", str(manifest), "--method", "equipartition",
               "--diffusion", f"{d_um2:.8g}"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert "pN/nm" in cap.out and "um^2/s" in cap.out and "method: equipartition" in cap.out
    # ... and as JSON (SI units)
    rc = main(["calibrate", str(manifest), "--method", "equipartition",
               "--diffusion", f"{d_um2:.8g}", "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    res = json.loads(cap.out)
    assert res["units"] == "SI"
    assert res["k"] == pytest.approx([2e-5, 4e-5], rel=0.1)
    # naive equipartition is biased high by the blur
    rc = main(["calibrate", str(manifest), "--method", "equipartition", "--json"])
    naive = json.loads(capsys.readouterr().out)["k"]
    assert naive[1] > res["k"][1] * 1.05


def test_format_result_lab_units():
    """The calibrate table converts every parameter to lab units (c: N/m/W -> pN/nm/W)."""
    import numpy as np

    from blurtrap.cli import format_result
    from blurtrap.inference import CalibrationResult

    res = CalibrationResult(
        method="variance_vs_power", model="standard", param_names=("c", "gamma", "tracking_var"),
        values=np.array([1e-4, 2.74e-8, 4e-18]), covariance=np.diag([1e-12, 1e-18, 1e-36]),
        temperature=295.0, k_per_recording=np.array([1e-5, 2e-5]),
        k_per_recording_err=np.array([1e-7, 2e-7]), gof={}, n_recordings=2, n_frames=100)
    table = format_result(res)
    # the 95 % interval column (after the unit) is parsed apart from the value columns
    rows = {ln.split()[0]: ln.split("[")[0].split() for ln in table.splitlines()[2:]}
    assert float(rows["c"][1]) == pytest.approx(0.1) and rows["c"][-1] == "pN/nm/W"
    c_line = next(ln for ln in table.splitlines() if ln.split()[:1] == ["c"])
    lo, hi = (float(v) for v in c_line.split("[")[1].split("]")[0].split(","))
    assert (lo, hi) == (pytest.approx(0.1 - 1.96 * 0.001, rel=1e-3),
                        pytest.approx(0.1 + 1.96 * 0.001, rel=1e-3))  # lab units too
    assert float(rows["gamma"][1]) == pytest.approx(0.0274)
    assert " ".join(rows["gamma"][-2:]) == "pN s/um"
    assert float(rows["tracking_var"][1]) == pytest.approx(4.0)
    assert "um^2/s" in table and "k (recording 1)" in table
    d = next(ln for ln in table.splitlines() if ln.strip().startswith("D = kT/gamma"))
    assert float(d.split()[3]) == pytest.approx(KT / 2.74e-8 * 1e12, rel=1e-5)


def _one_error_line(err, command):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"blurtrap {command}: error: ")
    return lines[0]


def test_errors_are_one_line(tmp_path, capsys):
    assert main(["calibrate", str(tmp_path / "missing.json")]) == 1
    line = _one_error_line(capsys.readouterr().err, "calibrate")
    assert "missing.json" in line

    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert main(["calibrate", str(bad)]) == 1
    _one_error_line(capsys.readouterr().err, "calibrate")

    # exposure longer than the frame interval
    assert main(["simulate", "--k", "0.02", "--gamma", "0.0274", "--exposure-ms", "2",
                 "--fps", "1500", "--out", str(tmp_path / "x")]) == 1
    line = _one_error_line(capsys.readouterr().err, "simulate")
    assert "frame interval" in line

    # usage errors: one line too (argparse, exit 2)
    assert main(["simulate", "--k", "0.02"]) == 2
    _one_error_line(capsys.readouterr().err, "simulate")
    assert main(["calibrate", "m.json", "--method", "nonsense"]) == 2
    _one_error_line(capsys.readouterr().err, "calibrate")


def test_debug_shows_traceback(tmp_path):
    with pytest.raises(Exception, match="no such file"):
        main(["--debug", "calibrate", str(tmp_path / "missing.json")])
    with pytest.raises(Exception, match="no such file"):
        main(["calibrate", str(tmp_path / "missing.json"), "--debug"])


def test_diagnose_and_posterior_from_the_cli(tmp_path, capsys):
    out = tmp_path / "sim"
    assert main(["simulate", "--k", "0.05", "--radius", "1.53", "--exposure-ms", "0.6667",
                 "--fps", "1500", "--frames", "16384", "--tracking-nm", "2", "--seed", "3",
                 "--out", str(out), "--json"]) == 0
    capsys.readouterr()
    manifest = str(out / "manifest.json")
    assert main(["diagnose", manifest, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert isinstance(d["adequate"], bool)
    assert set(d["gof"]) >= {"statistic", "dof", "p"}
    for item in d["ranking"]:
        assert set(item) >= {"effect", "delta_loglik", "p_value", "delta_aic", "evidence"}
    assert main(["diagnose", manifest, "--model", "naive"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("model: naive") and "goodness of fit" in text
    assert main(["diagnose", manifest, "--add", "nonsense"]) == 1
    assert "unknown effect 'nonsense'" in capsys.readouterr().err
    from blurtrap import ShortChainWarning

    with pytest.warns(ShortChainWarning, match="shorter than 50 integrated autocorrelation"):
        rc = main(["calibrate", manifest, "--posterior", "--steps", "150", "--walkers", "12",
                   "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res["posterior"]["method"] == "posterior"
    assert res["posterior"]["k"] == pytest.approx(res["k"], rel=0.1)


CLI_BAD_INPUTS = [
    (["calibrate", "{tmp}/empty.json"], "empty"),
    (["calibrate", "{tmp}/obj.json"], "position_unit"),
    (["calibrate", "{tmp}/trace.csv"], "bare CSV"),
    (["calibrate", "{tmp}"], "directory"),
    (["diagnose", "{tmp}/trace.csv"], "bare CSV"),
    (["calibrate", "{tmp}/sim/manifest.json", "--method", "psd", "--n-blocks", "0"], "n_blocks"),
    (["calibrate", "{tmp}/sim/manifest.json", "--n-blocks", "0"], "n_blocks must be an integer"),
    (["calibrate", "{tmp}/sim/manifest.json", "--exclude", "0", "750"],
     "excluded ranges .* leave 0 of the"),
    (["calibrate", "{tmp}/sim/manifest.json", "--f-range", "2000", "3000"], "Nyquist"),
    (["calibrate", "{tmp}/sim/manifest.json", "--f-range", "100", "10"], "--f-range FMIN FMAX needs"),
    (["calibrate", "{tmp}/sim/manifest.json", "--method", "equipartition", "--diffusion", "3e5"],
     "um\\^2/s"),
    (["calibrate", "{tmp}/sim/manifest.json", "--method", "psd", "--diffusion", "0.3"],
     "diffusion"),
    # SI values given to lab-unit options (m^2/s to um^2/s, N s/m to pN s/um, m^2 to nm^2)
    (["calibrate", "{tmp}/sim/manifest.json", "--method", "equipartition", "--diffusion",
      "1.5e-13"], "looks like m\\^2/s"),
    (["calibrate", "{tmp}/sim/manifest.json", "--fix", "gamma=2.7e-8"],
     r"fixed\['gamma'\] = 2.7e-14 N s/m \(2.7e-08 pN s/um\) is outside"),
    (["calibrate", "{tmp}/sim/manifest.json", "--fix", "tracking_var=4e-18"],
     r"fixed\['tracking_var'\] = 4e-36 m\^2 .* unit slip"),
    (["calibrate", "{tmp}/sim/manifest.json", "--fix", "k=5000"], r"fixed\['k'\] = 5 N/m"),
    (["calibrate", "{tmp}/sim/manifest.json", "--k-mode", "linear_power"], "laser_power"),
    (["diagnose", "{tmp}/sim/manifest.json", "--add", "nonsense"], "unknown effect"),
    (["calibrate", "{tmp}/sim/manifest.json", "--f-range", "100", "5000"],
     "FMAX = 5000 Hz is above the Nyquist"),
    (["calibrate", "{tmp}/sim/manifest.json", "--method", "psd", "--f-range", "0", "750.5"],
     "above the Nyquist"),
    (["diagnose", "{tmp}/sim/manifest.json", "--alpha", "1.5"], "alpha .* 1.5"),
    (["diagnose", "{tmp}/sim/manifest.json", "--alpha", "-1"], "alpha .* -1"),
    (["diagnose", "{tmp}/sim/manifest.json", "--alpha", "nan"], "alpha .* nan"),
    (["simulate", "--k", "-1", "--radius", "1", "--exposure-ms", "0.5", "--out", "{tmp}/o"],
     "--k must be > 0"),
    (["simulate", "--k", "0.05", "--radius", "-1", "--exposure-ms", "0.5", "--out", "{tmp}/o"],
     "--radius"),
    (["simulate", "--k", "0.05", "--radius", "1", "--exposure-ms", "0.5", "--frames", "4",
      "--out", "{tmp}/o"], "--frames"),
    (["simulate", "--k", "0.05", "--radius", "1", "--exposure-ms", "0.5", "--fps", "0",
      "--out", "{tmp}/o"], "--fps"),
    (["simulate", "--k", "0.05", "0.1", "--radius", "1", "--exposure-ms", "0.5",
      "--power-mw", "10", "--out", "{tmp}/o"], "--power-mw"),
]


@pytest.fixture(scope="module")
def bad_input_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli_bad")
    (tmp / "empty.json").write_text("")
    (tmp / "obj.json").write_text("{}")
    (tmp / "trace.csv").write_text("t,x\n0,1\n")
    assert main(["simulate", "--k", "0.05", "--radius", "0.765", "--exposure-ms", "0.5",
                 "--frames", "2048", "--out", str(tmp / "sim")]) == 0
    return tmp


@pytest.mark.parametrize("argv,match", CLI_BAD_INPUTS, ids=[" ".join(a[:1] + a[2:])
                                                            for a, _ in CLI_BAD_INPUTS])
def test_cli_bad_inputs_give_one_clear_line(bad_input_dir, capsys, argv, match):
    capsys.readouterr()
    argv = [a.replace("{tmp}", str(bad_input_dir)) for a in argv]
    assert main(argv) == 1
    line = _one_error_line(capsys.readouterr().err, argv[0])
    assert re.search(match, line), line


# ------------------------------------------------------------------------------------------
# strict JSON: non-finite floats are null (JSON has no NaN; bare NaN literals break parsers)
# ------------------------------------------------------------------------------------------
def _strict_json(text):
    def reject(const):
        raise ValueError(f"non-standard JSON constant {const}")

    return json.loads(text, parse_constant=reject)


def test_calibrate_json_is_strict_with_nan_values(bad_input_dir, capsys):
    """Naive equipartition has no gamma (NaN before: a bare NaN literal); it prints null.
    The standard fit of a trace without tracking noise (eps^2 at its bound) stays strict."""
    manifest = str(bad_input_dir / "sim" / "manifest.json")
    capsys.readouterr()
    assert main(["calibrate", manifest, "--method", "equipartition", "--json"]) == 0
    res = _strict_json(capsys.readouterr().out)
    assert res["gamma"] is None and res["diffusion"] is None and res["k"] > 0
    assert main(["calibrate", manifest, "--json"]) == 0
    res = _strict_json(capsys.readouterr().out)
    assert "tracking_var" in res["at_bounds"]
    assert res["k"] > 0 and res["k_err"] > 0


def test_simulate_json_is_strict(tmp_path, capsys):
    assert main(["simulate", "--k", "0.05", "--radius", "0.765", "--exposure-ms", "0.5",
                 "--frames", "64", "--out", str(tmp_path / "s"), "--json"]) == 0
    assert _strict_json(capsys.readouterr().out)["n_recordings"] == 1


def test_diagnose_json_is_strict(bad_input_dir, capsys, monkeypatch):
    import blurtrap.diagnostics as diag

    class _Stub:
        def to_dict(self):
            return {"adequate": False, "gof": {"statistic": float("nan"), "dof": 3,
                                                "p_value": float("inf")},
                    "ranking": [{"effect": "drift", "delta_aic": float("-inf")}],
                    "fit": {"gamma_err": float("nan"), "k": 1e-5}}

    monkeypatch.setattr(diag, "diagnose", lambda *a, **kw: _Stub())
    capsys.readouterr()
    assert main(["diagnose", str(bad_input_dir / "sim" / "manifest.json"), "--json"]) == 0
    d = _strict_json(capsys.readouterr().out)
    assert d["gof"] == {"statistic": None, "dof": 3, "p_value": None, "p": None}
    assert d["ranking"][0]["delta_aic"] is None and d["fit"]["gamma_err"] is None


def test_demo_json_is_strict(tmp_path, capsys, monkeypatch):
    import numpy as np

    from blurtrap import _demo

    def fake_demo(out, quick=False, quiet=False, seed=0, **kw):
        return {"ok": True, "table": "t", "steps": [], "report": str(out),
                "figures": [], "runtime_s": 1.0, "posterior": "x",
                "naive": {"gamma": float("nan"), "k": np.float64(1e-5),
                          "errs": [np.nan, 2.0]}}

    monkeypatch.setattr(_demo, "demo", fake_demo)
    assert main(["demo", "--json", "--out", str(tmp_path)]) == 0
    out = _strict_json(capsys.readouterr().out)
    assert out["naive"] == {"gamma": None, "k": 1e-5, "errs": [None, 2.0]}


def test_dumps_json_strict_for_every_kind_of_value():
    import numpy as np

    from blurtrap.cli import dumps_json

    obj = {"a": float("nan"), "b": [float("inf"), -float("inf"), 1.5], "c": np.nan,
           "d": np.array([[1.0, np.nan]]), "e": np.float32("nan"), "f": (np.int64(3), True),
           "g": None, "h": "NaN"}
    assert _strict_json(dumps_json(obj)) == {"a": None, "b": [None, None, 1.5], "c": None,
                                             "d": [[1.0, None]], "e": None, "f": [3, True],
                                             "g": None, "h": "NaN"}


# ------------------------------------------------------------------------------------------
# arguments checked before any fitting
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv,match", [
    (["--posterior", "--steps", "0"], "--steps: must be an integer >= 10; got 0"),
    (["--posterior", "--steps", "-5"], "--steps"),
    (["--posterior", "--steps", "ten"], "--steps: must be an integer"),
    (["--posterior", "--walkers", "7"], "--walkers: must be an even integer"),
    (["--posterior", "--walkers", "0"], "--walkers"),
])
def test_posterior_arguments_rejected_before_fitting(bad_input_dir, capsys, monkeypatch, argv,
                                                     match):
    import blurtrap.inference as inf

    def boom(*a, **kw):
        raise AssertionError("calibrate ran before the arguments were checked")

    monkeypatch.setattr(inf, "calibrate", boom)
    monkeypatch.setattr(inf, "sample_posterior", boom)
    capsys.readouterr()
    rc = main(["calibrate", str(bad_input_dir / "sim" / "manifest.json"), *argv])
    assert rc == 2
    assert re.search(match, capsys.readouterr().err)


def test_model_with_effects_and_add_report_k_and_gamma(bad_input_dir, capsys):
    """'Add and refit' from the command line: --model accepts '+effect' (checked before any
    fitting), and diagnose --add prints the refitted k and gamma, not only the gof."""
    manifest = str(bad_input_dir / "sim" / "manifest.json")
    capsys.readouterr()
    assert main(["calibrate", manifest, "--model", "standard+drift", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["model"] == "standard+drift" and "drift_diffusion" in res["param_names"]
    assert main(["calibrate", manifest, "--model", "standard+warp"]) == 2
    assert "unknown effect 'warp'" in capsys.readouterr().err
    assert main(["diagnose", manifest, "--add", "drift"]) == 0
    text = capsys.readouterr().out
    assert "fit of the model standard+drift:" in text
    rows = {line.split()[0] for line in text.splitlines()[1:] if line.strip()}
    assert {"k", "gamma", "drift_diffusion"} <= rows
