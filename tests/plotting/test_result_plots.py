"""CalibrationResult.plot / .plot_residuals: the figures draw the fitted recordings' blocked
spectrum, the model the fit compared it with and the naive Lorentzian, each checked against a
reference computed here in numpy (periodogram by FFT, expected block periodogram from the
frame autocovariance, Lorentzian formula, Gamma quantiles from scipy)."""

import inspect
import math

import numpy as np
import pytest

import blurtrap as bt
from blurtrap.inference import CalibrationResult, get_model

plotting = pytest.importorskip("blurtrap.plotting")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from blurtrap.plotting._result_figs import gamma_ratio_quantile  # noqa: E402

KT = bt.BOLTZMANN * 295.0
GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
DT = 1 / 1500
EPS2 = 4e-18
NB = 16


def result_for(recs, ks, model="standard", extra=(), extra_values=(), **kw):
    """A CalibrationResult with given parameters that keeps `recs` (no fit: plots fit
    nothing, and the reference values are then known exactly)."""
    names = tuple(f"k[{i}]" for i in range(len(ks))) if len(ks) > 1 else ("k",)
    names += ("gamma",) + (("tracking_var",) if model == "standard" else ()) + tuple(extra)
    vals = np.array(list(ks) + [GAMMA] + ([EPS2] if model == "standard" else [])
                    + list(extra_values))
    res = CalibrationResult(
        method=kw.pop("method", "psd"), model=model, param_names=names, values=vals,
        covariance=np.diag((0.01 * vals) ** 2), temperature=295.0,
        k_per_recording=np.array(ks), k_per_recording_err=0.01 * np.array(ks), gof={},
        n_recordings=len(recs), n_frames=sum(r.n_frames for r in recs),
        extras={"n_blocks": NB})
    return res.with_inputs(recs, get_model(model), **kw)


def trace(rng, n=4096, scale=3e-8):
    return rng.standard_normal(n) * scale


def numpy_blocked_psd(x, dt, nb):
    """Two-sided blocked periodogram (block means removed), f > 0 up to Nyquist."""
    m = x.size // nb
    b = x[: m * nb].reshape(nb, m)
    b = b - b.mean(axis=1, keepdims=True)
    p = (np.abs(np.fft.rfft(b, axis=1)[:, 1:]) ** 2).mean(axis=0) * dt / m
    return np.arange(1, m // 2 + 1) / (m * dt), p


def expected_block_periodogram(f, m, k, gamma, w, dt, eps2):
    """(dt/m) sum_{|n|<m} (m - |n|) C(n) cos(2 pi f n dt) with the frame autocovariance of
    DESIGN item 5 (C(0) = sigma2 S + eps2, C(n) = sigma2 B rho^n): brute force over lags."""
    sigma2, tau = KT / k, gamma / k
    a = w / tau
    s = 2 / a - 2 * (1 - math.exp(-a)) / a**2
    b = 2 * (math.cosh(a) - 1) / a**2
    n = np.arange(1, m)
    c = sigma2 * b * np.exp(-n * dt / tau)
    lag = ((m - n)[None, :] * c[None, :] * np.cos(2 * np.pi * f[:, None] * n * dt)).sum(axis=1)
    return dt / m * (m * (sigma2 * s + eps2) + 2 * lag)


def lines(fig):
    return {ln.get_label(): ln for ln in fig.axes[0].get_lines()}


def test_spectrum_has_data_fit_and_naive_lorentzian(rng):
    rec = bt.Recording(trace(rng), frame_interval=DT, exposure=DT)
    k = 5e-5
    fig = result_for([rec], [k]).plot()
    assert isinstance(fig, Figure) and plt.fignum_exists(fig.number)  # shown by Jupyter
    ls = lines(fig)
    data = next(v for n, v in ls.items() if n.startswith("data"))
    f, p = numpy_blocked_psd(rec.positions, DT, NB)
    np.testing.assert_allclose(data.get_xdata(), f, rtol=1e-12)
    np.testing.assert_allclose(data.get_ydata(), 2 * p * 1e18, rtol=1e-10)  # nm^2/Hz
    fit = ls["fit (standard)"]
    ref = expected_block_periodogram(f, 4096 // NB, k, GAMMA, DT, DT, EPS2)
    np.testing.assert_allclose(fit.get_ydata(), 2 * ref * 1e18, rtol=1e-8)
    naive = ls["naive Lorentzian, same k and gamma"]
    fc, d = k / (2 * math.pi * GAMMA), KT / GAMMA
    np.testing.assert_allclose(naive.get_ydata(), d / (math.pi**2 * (fc**2 + f**2)) * 1e18,
                               rtol=1e-10)
    assert fig.axes[0].get_xscale() == "log" and "nm$^2$/Hz" in fig.axes[0].get_ylabel()
    assert "0.05 pN/nm" in fig.axes[0].get_title()


def test_naive_model_draws_no_naive_comparison(rng):
    rec = bt.Recording(trace(rng), frame_interval=DT, exposure=DT)
    ls = lines(result_for([rec], [5e-5], model="naive").plot())
    assert not any("Lorentzian" in n for n in ls)
    f, _ = numpy_blocked_psd(rec.positions, DT, NB)
    fc = 5e-5 / (2 * math.pi * GAMMA)
    np.testing.assert_allclose(ls["fit (naive)"].get_ydata(),
                               KT / GAMMA / (math.pi**2 * (fc**2 + f**2)) * 1e18, rtol=1e-10)


def test_each_recording_with_its_own_stiffness_and_into_given_axes(rng):
    recs = [bt.Recording(trace(rng), frame_interval=DT, exposure=w) for w in (1e-4, DT)]
    ks = [3e-5, 6e-5]
    fig0, ax = plt.subplots()
    fig = result_for(recs, ks).plot(ax=ax)
    assert fig is fig0 and len(fig.axes) == 1
    models = [ln for ln in ax.get_lines() if ln.get_linestyle() == "-"]
    assert len(models) == 2
    m = 4096 // NB
    for ln, w, k in zip(models, (1e-4, DT), ks, strict=True):
        f = ln.get_xdata()
        ref = expected_block_periodogram(f, m, k, GAMMA, w, DT, EPS2)
        np.testing.assert_allclose(ln.get_ydata(), 2 * ref * 1e18, rtol=1e-8)


def test_volts_are_scaled_by_the_displacement_sensitivity(rng):
    x = trace(rng)
    rd = 2.5e-7  # m/V
    rec_v = bt.Recording(x / rd, frame_interval=DT, exposure=DT, position_unit="V")
    res = result_for([rec_v], [5e-5], extra=("displacement_sensitivity",),
                     extra_values=(rd,))
    data = next(v for n, v in lines(res.plot()).items() if n.startswith("data"))
    _, p = numpy_blocked_psd(x, DT, NB)
    np.testing.assert_allclose(data.get_ydata(), 2 * p * 1e18, rtol=1e-9)


@pytest.mark.parametrize("n, method, blocks", [(8192, "likelihood", 16), (65536, "exact", 32),
                                               (1024, "allan", 2), (8192, "psd", NB)])
def test_default_block_count(rng, n, method, blocks):
    """A blocked fit's own count; otherwise at most 32 blocks of at least 512 frames."""
    rec = bt.Recording(trace(rng, n), frame_interval=DT, exposure=DT)
    data = next(v for k, v in lines(result_for([rec], [5e-5], method=method).plot()).items()
                if k.startswith("data"))
    assert data.get_label().startswith(f"data: {blocks} blocks")
    assert data.get_xdata()[0] == pytest.approx(blocks / (n * DT))  # lowest frequency


def test_unfitted_bands_are_shaded(rng):
    rec = bt.Recording(trace(rng), frame_interval=DT, exposure=DT)
    fig = result_for([rec], [5e-5], excluded=[(100.0, 150.0)]).plot()
    spans = [p for p in fig.axes[0].patches if p.get_label() == "not fitted"]
    assert len(spans) == 1
    span = spans[0]  # a Rectangle (matplotlib >= 3.9) or a Polygon
    xs = ([span.get_x(), span.get_x() + span.get_width()] if hasattr(span, "get_width")
          else np.asarray(span.get_xy())[:, 0])
    assert (min(xs), max(xs)) == (pytest.approx(100.0), pytest.approx(150.0))
    fig = result_for([rec], [5e-5], f_range=(10.0, 500.0)).plot_residuals()
    spans = list(fig.axes[0].patches)  # the shaded bands are the only patches
    ends = sorted((round(min(x), 6), round(max(x), 6)) for x in (
        [p.get_x(), p.get_x() + p.get_width()] if hasattr(p, "get_width")
        else np.asarray(p.get_xy())[:, 0] for p in spans))
    f, _ = numpy_blocked_psd(rec.positions, DT, NB)
    assert ends == [(round(f[0], 6), 10.0), (500.0, round(f[-1], 6))]


@pytest.mark.parametrize("nb", [1, 2, 7, 128])
def test_gamma_ratio_quantiles_match_scipy(nb):
    stats = pytest.importorskip("scipy.stats")
    q = [0.025, 0.16, 0.5, 0.84, 0.975]
    np.testing.assert_allclose(gamma_ratio_quantile(q, nb),
                               stats.gamma.ppf(q, a=nb, scale=1 / nb), rtol=1e-9)
    with pytest.raises(ValueError, match="quantile levels"):
        gamma_ratio_quantile([1.0], nb)


def test_residuals_ratio_and_expected_band(rng):
    stats = pytest.importorskip("scipy.stats")
    rec = bt.Recording(trace(rng), frame_interval=DT, exposure=DT)
    k = 5e-5
    fig = result_for([rec], [k]).plot_residuals()
    ax = fig.axes[0]
    pts = next(ln for ln in ax.get_lines() if ln.get_label().startswith("data / model"))
    f, p = numpy_blocked_psd(rec.positions, DT, NB)
    ratio = p / expected_block_periodogram(f, 4096 // NB, k, GAMMA, DT, DT, EPS2)
    np.testing.assert_allclose(pts.get_ydata(), ratio, rtol=1e-8)
    outside = np.mean((ratio < stats.gamma.ppf(0.025, NB, scale=1 / NB))
                      | (ratio > stats.gamma.ppf(0.975, NB, scale=1 / NB))) * 100
    assert f"{outside:.1f} % outside the 95 % band" in pts.get_label()
    band = next(c for c in ax.collections if c.get_label().startswith("95 % band"))
    ys = band.get_paths()[0].vertices[:, 1]
    assert (ys.min(), ys.max()) == (
        pytest.approx(stats.gamma.ppf(0.025, NB, scale=1 / NB), rel=1e-9),
        pytest.approx(stats.gamma.ppf(0.975, NB, scale=1 / NB), rel=1e-9))
    assert "n_b = 16" in band.get_label()


def test_clear_errors_without_recordings_or_friction(rng):
    rec = bt.Recording(trace(rng), frame_interval=DT, exposure=DT)
    bare = CalibrationResult(
        method="psd", model="standard", param_names=("k", "gamma"),
        values=np.array([5e-5, GAMMA]), covariance=np.eye(2) * 1e-20, temperature=295.0,
        k_per_recording=np.array([5e-5]), k_per_recording_err=np.array([1e-6]), gof={},
        n_recordings=1, n_frames=4096)
    for draw in (bare.plot, bare.plot_residuals):
        with pytest.raises(ValueError, match="holds no recordings.*fig6_psd"):
            draw()
    equi = CalibrationResult(
        method="equipartition", model="naive", param_names=("k",), values=np.array([5e-5]),
        covariance=np.eye(1) * 1e-12, temperature=295.0, k_per_recording=np.array([5e-5]),
        k_per_recording_err=np.array([1e-6]), gof={}, n_recordings=1,
        n_frames=4096).with_inputs([rec], get_model("naive"))
    with pytest.raises(ValueError, match=r"'equipartition'\) has no friction gamma \(gamma "
                                         r"= nan"):
        equi.plot()
    with pytest.raises(ValueError, match="n_blocks must be an integer >= 1.*got n_blocks = 0"):
        result_for([rec], [5e-5]).plot(n_blocks=0)


def synth(k, n, rng):
    """Gaussian frames with exactly the standard model's discrete spectrum (circulant
    synthesis in numpy: no simulator compile)."""
    from blurtrap.plotting._common import model_psd

    rec0 = bt.Recording(trace(rng, 8), frame_interval=DT, exposure=DT)
    f = np.fft.rfftfreq(n, DT)
    f[0] = 1.0
    p = model_psd({"k": k, "gamma": GAMMA, "tracking_var": EPS2}, rec0, f)
    z = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / math.sqrt(2)
    z[0], z[-1] = 0.0, rng.standard_normal()
    return np.fft.irfft(np.sqrt(p * n / DT) * z, n)


def test_calibrate_keeps_its_inputs_but_json_does_not(rng):
    """A real fit: the result keeps the recording and model it fitted (not serialised), and
    its figure's model line is the fitted model at the fitted parameters."""
    n = 4096
    rec = bt.Recording(synth(5e-5, n, rng), frame_interval=DT, exposure=DT)
    res = bt.calibrate(rec, method="psd", n_blocks=NB)
    assert res.inputs.recordings[0] is rec and res.inputs.model.name == "standard"
    assert "inputs" not in res.to_dict() and "FitInputs" not in str(res.to_dict())
    fit = lines(res.plot())["fit (standard)"]
    ref = expected_block_periodogram(fit.get_xdata(), n // NB, res.k, res.gamma, DT, DT,
                                     res.tracking_var)
    np.testing.assert_allclose(fit.get_ydata(), 2 * ref * 1e18, rtol=1e-8)


def test_volts_calibration_draws_metres(rng):
    """Positions in volts with the bead's Stokes friction: the figures are in nm^2/Hz (data
    scaled by the fitted Rd^2) and data/model averages 1 (128 ordinates of SD 1/4 each: the
    mean's SD is 0.022; 4 SD allowed)."""
    n, rd = 4096, 1e-7
    x = synth(5e-5, n, rng)
    rec = bt.Recording(x / rd, frame_interval=DT, exposure=DT, position_unit="V",
                       metadata={"friction": "stokes", "bead_radius_m": 1.53e-6,
                                 "viscosity_Pa_s": 0.00093})
    # the reference below is the standard model's: no hydrodynamic friction of the bead
    res = bt.calibrate(rec, method="psd", n_blocks=NB, hydrodynamics=False)
    rd_fit = res["displacement_sensitivity"]
    assert abs(rd_fit.value - rd) < 4 * rd_fit.error
    pts = next(ln for ln in res.plot_residuals().axes[0].get_lines()
               if ln.get_label().startswith("data / model"))
    f, p = numpy_blocked_psd(x / rd, DT, NB)
    ref = expected_block_periodogram(f, n // NB, res.k, res.gamma, DT, DT, res.tracking_var)
    np.testing.assert_allclose(pts.get_ydata(), p * rd_fit.value**2 / ref, rtol=1e-8)
    assert abs(np.mean(pts.get_ydata()) - 1.0) < 4 * 0.25 / math.sqrt(f.size)


def test_every_public_figure_takes_ax_or_fig_and_returns_the_figure():
    """Audit of blurtrap.plotting: each figure function accepts ax= (one axes) or fig= (an
    empty figure, several axes)."""
    helpers = {"LAB_UNITS", "close", "save"}
    missing = []
    for name in plotting.__all__:
        if name in helpers:
            continue
        params = inspect.signature(getattr(plotting, name)).parameters
        if "ax" not in params and "fig" not in params:
            missing.append(name)
        doc = getattr(plotting, name).__doc__ or ""
        assert "Returns" in doc or "Returns the figure" in doc or "returns" in doc, name
    assert not missing, f"figure functions without ax=/fig=: {missing}"
    assert {"fit_spectrum", "fit_residuals"} <= set(plotting.__all__)
