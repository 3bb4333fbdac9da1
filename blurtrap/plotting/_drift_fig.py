"""The paper's Fig. 5: drift removal by high-pass filtering, the variance vs the cut-off
frequency and its linear extrapolation to 0 Hz (appendix B)."""

from __future__ import annotations

import math

import numpy as np

from ._common import NM2, blur_factor_np, kT, model_psd, new_axes, trap_params


# --------------------------------------------------------------------------------------------
# Figure 5: drift (appendix B)
# --------------------------------------------------------------------------------------------
def fig5_highpass(
    recording,
    corner_frequency=None,
    *,
    params=None,
    fraction=(0.1, 0.5),
    n_cut=20,
    f_max=None,
    ax=None,
):
    r"""Fig. 5: variance vs high-pass cut-off and its linear extrapolation to 0 Hz (appendix
    B; :func:`blurtrap.inference.drift_extrapolation`).

    - `recording`: a ``Recording`` (possibly with drift).
    - `corner_frequency` f_c [Hz]; default ``k/(2 pi gamma)`` from `params`.
    - `params`: optional true/fitted trap (``CalibrationResult``, mapping or tuple); when
      given, the expected curve ``C(0) - 2 int_0^f1 P_d(f) df`` of the drift-free model is
      drawn (its slope at 0 is ``-2 P_d(0)``, DESIGN item 8).
    - `fraction`: the fitted range of cut-offs as fractions of f_c.
    - `f_max` [Hz]: largest cut-off shown (default ``min(1.2 f_c, Nyquist)``).

    **Returns:** Figure with one axes (cut-off in Hz, variance in nm^2).
    """
    from ..inference import drift_extrapolation, highpass_variance_curve

    dt = float(recording.frame_interval)
    if corner_frequency is None:
        if params is None:
            raise ValueError("give corner_frequency [Hz] or params (k, gamma) to set it")
        k, g, _, _ = trap_params(params)
        corner_frequency = k / (2 * math.pi * g)
    fc = float(corner_frequency)
    y = np.asarray(recording.positions)
    v0, slope, cut, v = drift_extrapolation(y, dt, corner_frequency=fc, fraction=fraction,
                                            n_cut=n_cut)
    nyq = 0.5 / dt
    fm = float(f_max) if f_max is not None else min(1.2 * fc, nyq)
    grid = np.linspace(0.0, fm, 300)
    vg = highpass_variance_curve(y, dt, grid)
    v_unf = float(np.var(y))
    fig, ax = new_axes(figsize=(6.0, 4.4), ax=ax)
    ax.plot(grid, vg * NM2, color="0.55", lw=1.0, label="variance after ideal high-pass")
    ax.plot(cut, v * NM2, "o", color="C0", ms=4, label="fitted cut-offs")
    fl = np.linspace(0.0, cut.max(), 50)
    ax.plot(fl, (v0 + slope * fl) * NM2, color="C3", ls="--", lw=1.5,
            label=f"linear fit, slope {slope * NM2:.3g} nm$^2$/Hz")
    ax.plot([0.0], [v0 * NM2], "*", color="C3", ms=14,
            label=f"extrapolated to 0 Hz: {v0 * NM2:.4g} nm$^2$")
    ax.plot([0.0], [v_unf * NM2], "x", color="k", ms=10, mew=2,
            label=f"unfiltered: {v_unf * NM2:.4g} nm$^2$")
    if params is not None:
        k, g, e2, t = trap_params(params)
        fine = np.linspace(0.0, fm, 2000)
        fine[0] = 1e-9 * fm
        pd = model_psd(params, recording, fine, model="standard")
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (pd[1:] + pd[:-1]) * np.diff(fine))])
        c0 = kT(t) / k * float(blur_factor_np(float(recording.exposure) * k / g)) + e2
        ax.plot(fine, (c0 - 2.0 * cum) * NM2, color="k", ls=":", lw=1.2,
                label=f"drift-free model (C(0) = {c0 * NM2:.4g} nm$^2$)")
    ax.axvline(fc, color="0.7", lw=0.8, ls="-")
    ax.text(fc, ax.get_ylim()[1], " f_c", va="top", fontsize=8, color="0.4")
    ax.set_xlim(left=-0.02 * fm)
    ax.set_xlabel("high-pass cut-off frequency [Hz]")
    ax.set_ylabel("variance [nm$^2$]")
    ax.set_title(f"Fig. 5: drift removal by extrapolation (f_c = {fc:.4g} Hz)")
    ax.legend(fontsize=8)
    return fig


__all__ = ["fig5_highpass"]
