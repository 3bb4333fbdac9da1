r"""Instruments around the trap: a sinusoidal stage drive (``stage_drive``) and the detector's
volts-per-metre scaling.

Stage drive (active calibration; Tolic-Norrelykke et al., Rev. Sci. Instrum. 77, 103101
(2006)). The stage moves as ``x_s(t) = A sin(2 pi f_d t + phi)``. Two ways it reaches the
recorded trace (``StageDrive(mode=...)``):

- ``"fluid"`` (default, the active calibration of Tolic-Norrelykke): the stage carries the
  sample chamber, so the fluid moves while the trap and the detector stay fixed. The bead
  relative to the trap obeys ``gamma dx/dt = -k x + gamma dx_s/dt + thermal force``; the
  equation is linear, so ``x = x_thermal + x_drive`` with the exact steady-state response

  $$x_{drive}(t) = \mathrm{Im}\big[A\,H(f_d)\,e^{i(2\pi f_d t + \phi)}\big],\qquad
    H(f) = \frac{i f}{f_c + i f},\quad f_c = \frac{k}{2\pi\gamma}.$$

- ``"additive"``: the stage motion itself appears in the trace and does not disturb the bead
  relative to the trap (trap and fluid move together with the stage, e.g. a camera in the lab
  frame watching a moving trap): ``x_meas = x_thermal + x_s``, i.e. ``H = 1``.

In both modes the drive term then goes through the same detector as the thermal motion: an
optional :class:`PhotodiodeFilter` multiplies it by ``H_pd(f_d)``, and the exposure average
over ``[t_n, t_n + W]`` (frames start at ``t_n``) is exact for a sinusoid,

$$\frac{1}{W}\int_{t_n}^{t_n+W} e^{i\omega t}\,dt
  = e^{i\omega (t_n + W/2)}\ \mathrm{sinc}(f_d W),\qquad \mathrm{sinc}(u) = \frac{\sin \pi u}{\pi u}.$$

The recorded stage position (a nanostage readout) is ``x_s(t_n)`` at the frame start times,
instantaneous: :func:`stage_positions`.

Volts: :class:`Sensitivity` ``(rd)`` turns the frames into detector volts, ``x_V = x_m / Rd``
(``Rd`` [m/V]); it is applied last, after tracking noise, so ``tracking_std`` stays in metres
(tracking noise of ``e_V`` volts is ``tracking_std = e_V * Rd``).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..effects.injections import StageDrive as StageDrive
from ..effects.injections import check_scalar as _scalar


class Sensitivity(eqx.Module):
    """Detector volts (``x_V = x_m / rd``): the displacement sensitivity ``rd`` [m/V] of the
    detector. Passed in ``injections=``, it is applied last (after the tracking noise, the
    drift and the stage drive), so the output is in volts; ``tracking_std`` stays in metres.

    - `rd`: displacement sensitivity Rd [m/V], > 0 (e.g. ``100e-9`` for 100 nm/V).
    """

    rd: Float[Array, ""]
    name = "sensitivity"

    def __init__(self, rd):
        self.rd = jnp.asarray(_scalar("rd", rd, "m/V", positive=True))


def stage_positions(drive: StageDrive, frame_interval, n_frames: int, *, start=0.0):
    """Recorded stage positions [m], shape ``(n_frames,)``: ``x_s(start + n frame_interval)``,
    the stage read out at each frame's start time, instantaneous (NumPy, float64). With
    :class:`TimingJitter` use ``drive.position(times)`` with the times of
    ``simulate(..., return_times=True)``."""
    if isinstance(n_frames, bool) or not isinstance(n_frames, int | np.integer) or n_frames < 1:
        raise ValueError(f"n_frames must be an integer >= 1; got n_frames = {n_frames!r}")
    dt = _scalar("frame_interval", frame_interval, "s", positive=True)
    return drive.position(start + dt * np.arange(int(n_frames)))


def drive_frames(drives, kf, gf, widths, dtf, n_frames, times, photodiode, dtype):
    """Sum of the drives' frame terms [m], shape ``(G, n_win, T', n_frames)``.

    `kf`, `gf`, `dtf`: (G,) float64; `widths`: (G, n_win) exposure durations [s] in the user's
    window order; `times`: jittered frame start times [s] ``(G, T, n)`` (a JAX array), or
    ``None`` for regular frames ``t_n = n dt`` (phases then computed in float64 on the host,
    so float32 runs keep their accuracy over long records)."""
    total = None
    for drv in drives:
        g = drv.frame_gain(kf[:, None], gf[:, None], widths, photodiode)  # (G, n_win)
        gr = jnp.asarray(drv.amplitude * g.real, dtype)[:, :, None, None]
        gi = jnp.asarray(drv.amplitude * g.imag, dtype)[:, :, None, None]
        w = 2.0 * np.pi * drv.frequency
        if times is None:
            cyc = np.mod(drv.frequency * dtf[:, None] * np.arange(n_frames), 1.0)
            th = jnp.asarray(2.0 * np.pi * cyc + drv.phase, dtype)[:, None, None, :]
        else:
            th = (jnp.asarray(w, dtype) * times + jnp.asarray(drv.phase, dtype))[:, None]
        term = gr * jnp.sin(th) + gi * jnp.cos(th)
        total = term if total is None else total + term
    return total


def check_drives(drives, sensitivities, hydro, force, exposure_profile):
    """The combinations the drive hook cannot simulate exactly: ValueError."""
    if len(sensitivities) > 1:
        raise ValueError("at most one Sensitivity may be given in injections")
    fluid = any(d.mode == "fluid" for d in drives)
    if fluid and hydro is not None:
        raise ValueError("StageDrive(mode='fluid') with HydrodynamicFriction is not supported "
                         "(the response of a sphere to an oscillating fluid is not H = i f/(f_c + i f))")
    if fluid and force is not None:
        raise ValueError("StageDrive(mode='fluid') needs the harmonic trap (its response is "
                         "linear); it cannot be combined with a custom force")
    if drives and exposure_profile is not None:
        raise ValueError("StageDrive supports the rectangular exposure only (no exposure_profile)")
