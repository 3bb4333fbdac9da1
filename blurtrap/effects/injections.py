r"""The simulator's injections: what each effect's ``to_injection`` hook hands to
:func:`blurtrap.simulate.simulate` (they live here, below the simulator, so that an effect can
build its own; ``blurtrap.simulate`` re-exports them under the same names).

An injection is a small ``eqx.Module`` with array parameters (SI units). Additive injections
implement :meth:`AbstractInjection.apply`, called once after the frame scan, per grid point,
with the frames in metres; they never touch the Brownian-dynamics loop. :class:`TimingJitter`
is the one effect that must act inside the loop (it moves the frame start times); it is passed
in the same ``injections=`` tuple and picked out by :func:`blurtrap.simulate.simulate`.

Two more effects change the dynamics or the detector itself and select their own exact
sampler inside :func:`~blurtrap.simulate.simulate`: :class:`PhotodiodeFilter`
(``detector_filter``: exact joint linear system, ``method="exact_frames"`` or
``"spectral"``) and :class:`HydrodynamicFriction` (``hydrodynamics``: frequency-dependent
friction, ``method="spectral"``). :class:`TrapezoidProfile` (``exposure_kernel``) is an
exposure profile (``simulate(..., exposure_profile=...)``), not an injection.

Canonical effect names (DESIGN section 3): ``tracking_noise`` (:class:`TrackingNoise`),
``drift`` (:class:`RandomWalkDrift`, :class:`SinusoidDrift`), ``line_noise``
(:class:`SinusoidDrift` at the line's frequency), ``timing_jitter`` (:class:`TimingJitter`),
``detector_filter`` (:class:`PhotodiodeFilter`), ``hydrodynamics``
(:class:`HydrodynamicFriction`), ``exposure_kernel`` (:class:`TrapezoidProfile`),
``stage_drive`` (:class:`StageDrive`).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import Array, Float

from ..physics import POLYSTYRENE_DENSITY


def _nonneg(name, value, unit):
    arr = np.asarray(value, dtype=np.float64)
    if not (np.all(np.isfinite(arr)) and np.all(arr >= 0)):
        raise ValueError(f"{name} must be finite and >= 0 {unit}; got {name} = {arr!r} {unit}")
    return jnp.asarray(value)


def _pos(name, value, unit):
    arr = np.asarray(value, dtype=np.float64)
    if not (np.all(np.isfinite(arr)) and np.all(arr > 0)):
        raise ValueError(f"{name} must be finite and > 0 {unit}; got {name} = {arr!r} {unit}")
    return jnp.asarray(value)


class AbstractInjection(eqx.Module):
    """An additive effect applied after the scan.

    ``apply(x, times, key)``: `x` frames [m] of shape ``(..., n_traces, n_frames)`` (one grid
    point; a leading windows axis may be present), `times` frame start times [s] broadcastable
    to `x`, `key` a PRNG key owned by this injection. Returns the new frames (same shape/dtype).
    """

    name: eqx.AbstractClassVar[str]

    @abc.abstractmethod
    def apply(self, x, times, key):
        ...


class TrackingNoise(AbstractInjection):
    """White tracking noise (``tracking_noise``): i.i.d. ``N(0, std^2)`` added to every frame.

    - `std`: tracking-error standard deviation eps [m], >= 0.
    """

    std: Float[Array, ""]
    name = "tracking_noise"

    def __init__(self, std):
        self.std = _nonneg("std", std, "m")

    def apply(self, x, times, key):
        return x + self.std.astype(x.dtype) * jr.normal(key, x.shape, x.dtype)


class RandomWalkDrift(AbstractInjection):
    """Random-walk drift (``drift``): ``d(t)`` with ``var(d(t) - d(s)) = 2 D |t - s|``, d(0) = 0,
    sampled at the frame start times; each trace (and each window axis entry shares the
    trace's drift) gets its own walk.

    - `diffusion`: drift diffusion coefficient D_drift [m^2/s], >= 0.
    """

    diffusion: Float[Array, ""]
    name = "drift"

    def __init__(self, diffusion):
        self.diffusion = _nonneg("diffusion", diffusion, "m^2/s")

    def apply(self, x, times, key):
        t = jnp.broadcast_to(times, x.shape[-2:]).astype(x.dtype)
        dt = jnp.diff(t, axis=-1, prepend=t[..., :1])
        steps = jnp.sqrt(2.0 * self.diffusion.astype(x.dtype) * jnp.maximum(dt, 0.0))
        walk = jnp.cumsum(steps * jr.normal(key, t.shape, x.dtype), axis=-1)
        return x + walk


class SinusoidDrift(AbstractInjection):
    """Slow sinusoidal drift (``drift``): ``amplitude * sin(2 pi t / period + phase)``.

    - `amplitude` [m] (>= 0); `period` [s] (> 0);
    - `phase` [rad] or ``None`` (default): a uniform random phase per trace.
    """

    amplitude: Float[Array, ""]
    period: Float[Array, ""]
    phase: Float[Array, ""] | None

    name = "drift"

    def __init__(self, amplitude, period, phase=None):
        self.amplitude = _nonneg("amplitude", amplitude, "m")
        self.period = _pos("period", period, "s")
        self.phase = None if phase is None else jnp.asarray(phase)

    def apply(self, x, times, key):
        n_traces = x.shape[-2]
        if self.phase is None:
            phase = jr.uniform(key, (n_traces, 1), x.dtype, 0.0, 2.0 * jnp.pi)
        else:
            phase = self.phase.astype(x.dtype)
        t = jnp.asarray(times).astype(x.dtype)
        w = (2.0 * jnp.pi / self.period).astype(x.dtype)
        return x + self.amplitude.astype(x.dtype) * jnp.sin(w * t + phase)


class TimingJitter(eqx.Module):
    """Irregular frame times (``timing_jitter``): frame n starts at ``n dt + delta_n``,
    ``delta_n ~ N(0, std^2)`` i.i.d. per frame and trace; the exposure keeps its length and the
    dead time between frames absorbs the jitter (``dt - W + delta_{n+1} - delta_n``, clipped at 0).

    Acts inside the frame scan (the Brownian motion is simulated at the jittered times);
    ``simulate(..., return_times=True)`` returns the actual start times.

    - `std`: timing-jitter standard deviation [s], >= 0; should be well below ``dt - W``.
    """

    std: Float[Array, ""]
    name = "timing_jitter"

    def __init__(self, std):
        self.std = _nonneg("std", std, "s")


class PhotodiodeFilter(eqx.Module):
    r"""Photodiode low-pass (``detector_filter``; Berg-Sorensen et al., Rev. Sci. Instrum. 74,
    3188 (2003)): a fraction `alpha` of the signal responds instantly, the rest through a
    first-order low-pass of corner `f3db`,

    $$H(f) = \alpha + \frac{1-\alpha}{1 + i f/f_{3dB}},\qquad
      |H|^2 = \alpha^2 + \frac{1-\alpha^2}{1 + (f/f_{3dB})^2}.$$

    The filter acts on the continuous position, before the exposure average and the sampling.
    With ``method="exact_frames"`` the position and the filter state are integrated as one
    exact linear Gaussian system (``blurtrap.simulate._linear``); ``method="spectral"`` draws
    the same law from its discrete PSD. Typical silicon photodiodes at 1064 nm: f3db ~ 5-10 kHz,
    alpha ~ 0.3-0.5.

    - `f3db`: 3 dB corner frequency of the slow part [Hz], > 0.
    - `alpha`: fraction of instantaneous response, in [0, 1].
    """

    f3db: float = eqx.field(static=True)
    alpha: float = eqx.field(static=True)
    name = "detector_filter"

    def __init__(self, f3db, alpha):
        f3 = float(f3db)
        al = float(alpha)
        if not (np.isfinite(f3) and f3 > 0):
            raise ValueError(f"f3db must be finite and > 0 Hz; got f3db = {f3db!r} Hz")
        if not (0.0 <= al <= 1.0):
            raise ValueError(f"alpha (instantaneous fraction) must be in [0, 1]; got alpha = "
                             f"{alpha!r}")
        self.f3db = f3
        self.alpha = al


class HydrodynamicFriction(eqx.Module):
    r"""Frequency-dependent friction of a sphere (``hydrodynamics``; Berg-Sorensen & Flyvbjerg,
    Rev. Sci. Instrum. 75, 594 (2004), eq. 12): Stokes friction with fluid inertia and the
    Basset force, plus the bead's and the entrained fluid's inertia,

    $$\gamma(f) = \gamma_0\Big(1 + (1-i)\sqrt{f/f_\nu} - \tfrac{2i}{9} f/f_\nu\Big),\quad
      f_\nu = \frac{\eta}{\pi\rho_f R^2},$$
    $$P(f) = \frac{D}{2\pi^2}\,\frac{1 + \sqrt{f/f_\nu}}
      {(f_c - f^{3/2}/\sqrt{f_\nu} - f^2/f_m)^2 + (f + f^{3/2}/\sqrt{f_\nu})^2},\quad
      f_m = \frac{\gamma_0}{2\pi m^*},\ m^* = \tfrac{4}{3}\pi R^3(\rho_b + \rho_f/2).$$
    Near a surface (``distance``) the frequency dependence is that of Tolic-Norrelykke et al.,
    Rev. Sci. Instrum. 77, 103101 (2006), eq. D6 (``blurtrap.physics.hydro_lorentzian``).

    ``gamma`` passed to :func:`simulate` is the zero-frequency friction gamma_0 (include
    Faxen's wall correction there, e.g. ``gamma = 6 pi eta R * faxen_factor(R, h)``); the
    radius (and the distance) set only the frequency dependence. Needs ``method="spectral"``
    (no Markovian simulation exists in the position alone).

    - `radius`: bead radius R [m], > 0.
    - `viscosity`: fluid viscosity eta [Pa s] or ``None`` (water at the simulation
      temperature, ``blurtrap.physics.water_viscosity``, IAPWS 2008).
    - `fluid_density`: [kg/m^3] or ``None`` (water at the simulation temperature,
      ``blurtrap.physics.water_density``); `bead_density`: [kg/m^3] (default polystyrene,
      1050).
    - `distance`: bead centre to the surface [m], > radius, or ``None`` (bulk, the default).
    """

    radius: float = eqx.field(static=True)
    viscosity: float | None = eqx.field(static=True)
    fluid_density: float | None = eqx.field(static=True)
    bead_density: float = eqx.field(static=True)
    distance: float | None = eqx.field(static=True)
    name = "hydrodynamics"

    def __init__(self, radius, viscosity=None, fluid_density=None,
                 bead_density=POLYSTYRENE_DENSITY, distance=None):
        for nm, v, unit in (("radius", radius, "m"), ("bead_density", bead_density, "kg/m^3")):
            if not (np.isfinite(float(v)) and float(v) > 0):
                raise ValueError(f"{nm} must be finite and > 0 {unit}; got {nm} = {v!r} {unit}")
        for nm, v, unit, what in (("viscosity", viscosity, "Pa s", "water"),
                                  ("fluid_density", fluid_density, "kg/m^3", "water"),
                                  ("distance", distance, "m", "bulk")):
            if v is not None and not (np.isfinite(float(v)) and float(v) > 0):
                raise ValueError(f"{nm} must be finite and > 0 {unit} (or None for {what}); "
                                 f"got {nm} = {v!r} {unit}")
        if distance is not None and not float(distance) > float(radius):
            raise ValueError(f"distance (bead centre to surface) must exceed the radius; got "
                             f"distance = {distance!r} m with radius = {radius!r} m")
        self.radius = float(radius)
        self.viscosity = None if viscosity is None else float(viscosity)
        self.fluid_density = None if fluid_density is None else float(fluid_density)
        self.bead_density = float(bead_density)
        self.distance = None if distance is None else float(distance)


class TrapezoidProfile(eqx.Module):
    """Linear rise over the first ``rise_fraction`` of the exposure and linear fall over the
    last; matches ``blurtrap.physics.TrapezoidKernel(exposure, rise=rise_fraction*exposure)``.
    An exposure profile for ``simulate(..., exposure_profile=...)`` (``exposure_kernel``)."""

    rise_fraction: float = eqx.field(static=True)

    def __init__(self, rise_fraction):
        r = float(rise_fraction)
        if not (0.0 <= r <= 0.5):
            raise ValueError(f"rise_fraction must be in [0, 0.5]; got rise_fraction = {r!r}")
        self.rise_fraction = r

    def __call__(self, u):
        u = np.asarray(u, dtype=np.float64)
        if self.rise_fraction == 0.0:
            return np.ones_like(u)
        r = self.rise_fraction
        return np.clip(np.minimum(u / r, (1.0 - u) / r), 0.0, 1.0)


_MODES = ("fluid", "additive")


def check_scalar(name, value, unit, positive):
    """``value`` as a float: a finite scalar, > 0 (`positive`) or >= 0; else a ValueError
    naming it, its value and the rule."""
    arr = np.asarray(value, dtype=np.float64)
    ok = arr.ndim == 0 and np.isfinite(arr) and (arr > 0 if positive else arr >= 0)
    if not ok:
        rule = "> 0" if positive else ">= 0"
        raise ValueError(f"{name} must be a finite scalar {rule} {unit}; got {name} = {value!r} {unit}")
    return float(arr)


class StageDrive(eqx.Module):
    r"""Sinusoidal stage drive (``stage_drive``): ``x_s(t) = amplitude sin(2 pi frequency t +
    phase)``, passed in ``simulate(..., injections=(StageDrive(...),))`` (or to
    :func:`simulate_photodiode`). See ``blurtrap.simulate._instruments`` for the two modes.

    - `amplitude`: A [m], >= 0.
    - `frequency`: f_d [Hz], > 0 (keep it below the Nyquist frequency of the frames).
    - `phase`: phi [rad] at t = 0 (the first frame's start), default 0.
    - `mode`: ``"fluid"`` (the stage moves the fluid; the bead responds through
      ``H(f) = i f/(f_c + i f)``) or ``"additive"`` (the trace contains ``x_s`` itself).

    Several drives (e.g. two frequencies) may be given; their terms add.
    """

    amplitude: float = eqx.field(static=True)
    frequency: float = eqx.field(static=True)
    phase: float = eqx.field(static=True)
    mode: str = eqx.field(static=True)
    name = "stage_drive"

    def __init__(self, amplitude, frequency, phase=0.0, mode="fluid"):
        self.amplitude = check_scalar("amplitude", amplitude, "m", positive=False)
        self.frequency = check_scalar("frequency", frequency, "Hz", positive=True)
        ph = np.asarray(phase, dtype=np.float64)
        if ph.ndim != 0 or not np.isfinite(ph):
            raise ValueError(f"phase must be a finite scalar [rad]; got phase = {phase!r}")
        self.phase = float(ph)
        if mode not in _MODES:
            raise ValueError(f"mode must be one of {_MODES}; got mode = {mode!r}")
        self.mode = mode

    def position(self, t):
        """Stage position ``x_s(t)`` [m] at times `t` [s] (NumPy, float64)."""
        t = np.asarray(t, dtype=np.float64)
        return self.amplitude * np.sin(2.0 * np.pi * self.frequency * t + self.phase)

    def response(self, k, gamma):
        """Complex transfer from the stage to the trace at the drive frequency: ``i f_d /
        (f_c + i f_d)`` with ``f_c = k / (2 pi gamma)`` (``"fluid"``), or 1 (``"additive"``).
        `k` [N/m] and `gamma` [N s/m] broadcast (NumPy)."""
        k = np.asarray(k, dtype=np.float64)
        gamma = np.asarray(gamma, dtype=np.float64)
        if self.mode == "additive":
            return np.ones(np.broadcast_shapes(k.shape, gamma.shape), dtype=np.complex128)
        fc = k / (2.0 * np.pi * gamma)
        return 1j * self.frequency / (fc + 1j * self.frequency)

    def frame_gain(self, k, gamma, exposure, photodiode=None):
        r"""Complex gain ``g`` of the frames: frame ``n`` holds ``Im[A g e^{i(2 pi f_d t_n +
        phi)}]`` (``t_n`` its start time) = ``response * H_pd(f_d) * sinc(f_d W) e^{i pi f_d W}``.
        `exposure` W [s] broadcasts with `k`, `gamma`; `photodiode` an optional
        :class:`PhotodiodeFilter`."""
        w = np.asarray(exposure, dtype=np.float64)
        f = self.frequency
        g = self.response(k, gamma) * np.sinc(f * w) * np.exp(1j * np.pi * f * w)
        if photodiode is not None:
            g = g * (photodiode.alpha + (1.0 - photodiode.alpha) / (1.0 + 1j * f / photodiode.f3db))
        return g
