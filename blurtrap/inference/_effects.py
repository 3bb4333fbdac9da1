r"""Physical effects: composable pieces of a trap model, by their canonical names.

A model is the harmonic trap plus effects (DESIGN section 3). Each effect has a canonical
``name``, its own parameters (:class:`Param`: unit, lab unit, typical scale, bounds) and one
hook into the signal chain:

=================  ==========  ==============================================================
name               kind        what it changes
=================  ==========  ==============================================================
motion_blur        flag        rectangular exposure average (closed form)
aliasing           flag        folding at fs (closed form)
tracking_noise     flag        white noise ``tracking_var`` (m^2)
drift              additive    random-walk drift PSD, ``drift_diffusion`` (m^2/s)
line_noise         additive    narrow line at a fixed frequency, ``line_amplitude`` (m)
exposure_kernel    transfer    trapezoidal exposure, ``rise_fraction`` (of W, 0-0.5)
detector_filter    transfer    photodiode filter, ``f3db`` (Hz) and ``diode_alpha`` (0-1)
hydrodynamics      friction    frequency-dependent Stokes friction, ``hydro_radius`` (m)
power_offset       relation    ``k = c (P - P0)``, ``power_offset`` (W)
laser_heating      relation    ``T = T0 + b P``, gamma follows water viscosity, ``heating`` (K/W)
anharmonicity      histogram   quartic term: non-Gaussian frame histogram (kurtosis test)
timing_jitter      timestamps  irregular frame times (from the recording's time stamps)
=================  ==========  ==============================================================

Transfer and friction effects make the model spectrum a folded sum (explicit |n| <= N plus
the exact sum of the 1/f^2 tail); flags and additive effects keep the closed form.

Detectability at realistic sizes (documented per effect below) matters: an effect that is too
weak to be seen in the data is reported as such by ``diagnose`` rather than guessed.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from ..physics import (
    POLYSTYRENE_DENSITY,
    hydro_lorentzian,
    water_density,
    water_viscosity,
)
from ..physics._constants import BOLTZMANN
from ..physics._effects import (
    drift_psd,
    line_psd,
    photodiode_transfer,
)


@dataclasses.dataclass(frozen=True)
class Param:
    name: str
    unit: str
    lab_factor: float
    lab_unit: str
    description: str
    upper: float = float("inf")


class AbstractEffect(eqx.Module):
    """An effect: canonical ``name``, ``kind``, ``params`` and hooks used by the model."""

    name: ClassVar[str] = ""
    kind: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    signature: ClassVar[str] = ""

    # additive discrete PSD term (R, M)
    def psd_add(self, f, dt, extras):
        return 0.0

    # multiplicative continuous transfer |H|^2 and its value at f -> infinity
    def transfer(self, f, w, extras):
        return 1.0

    def transfer_inf(self, extras):
        return 1.0


class MotionBlur(AbstractEffect):
    """Rectangular exposure average over W (paper eq. 1). Signature: PSD deficit rising
    toward fs/2; variance falls with W. A single blurred record looks like an unblurred one
    with a *negative* white-noise variance: with eps^2 >= 0 the naive model fails clearly."""

    name: ClassVar[str] = "motion_blur"
    kind: ClassVar[str] = "flag"
    signature: ClassVar[str] = "PSD deficit rising toward fs/2"


class Aliasing(AbstractEffect):
    """Folding of the spectrum at the sampling rate. Signature: excess near Nyquist."""

    name: ClassVar[str] = "aliasing"
    kind: ClassVar[str] = "flag"
    signature: ClassVar[str] = "excess near Nyquist vs the unfolded model"


class TrackingNoise(AbstractEffect):
    """White tracking error of variance eps^2. Signature: flat excess floor in the PSD."""

    name: ClassVar[str] = "tracking_noise"
    kind: ClassVar[str] = "flag"
    params: ClassVar = (Param("tracking_var", "m^2", 1e18, "nm^2", "tracking-error variance"),)
    signature: ClassVar[str] = "flat excess floor at high frequency"


class Drift(AbstractEffect):
    r"""Random-walk drift of diffusion ``drift_diffusion`` [m^2/s] (stage/laser): increments of
    variance ``2 D_d dt`` per frame, as injected by ``blurtrap.simulate.RandomWalkDrift``.

    **Model.** A random walk is not stationary: its periodogram is not its "PSD"
    ``D_d dt^2 / (2 sin^2(pi f dt))`` (the spectrum of the increments divided by
    ``|1 - e^{-i theta}|^2``, ``blurtrap.physics._effects.drift_psd``). Summation by parts gives
    the DFT of a walk ``y`` of N frames at a Fourier frequency ``theta_j = 2 pi j/N``,
    ``j != 0``: ``Y_j = (E_j - y_{N-1}) / (1 - e^{-i theta_j})`` with ``E_j`` the DFT of the
    increments; the end-to-end displacement ``y_{N-1}`` (the record's net drift, a ramp seen
    through the periodic DFT) adds exactly as much power as the increments, so the expected
    periodogram is **exactly twice** that PSD at every ``j >= 1`` (mean subtraction only
    touches j = 0; the same holds per block). This effect therefore models
    ``E[I(f)] = D_d dt^2 / sin^2(pi f dt)``, so that ``drift_diffusion`` estimates the walk's
    diffusion coefficient. (Before this correction the fitted value was 2.2 +- 0.16 times the
    injected one over 100 records; see benchmarks/RESULTS_diagnose.md.)

    **Its uncertainty is underestimated.** Half of the drift power is the one common ramp: the
    ordinates are not independent (correlation ~0.4 between low ordinates of a pure walk), so
    ``drift_diffusion`` scatters by ~70 % between records whatever their length (the net
    displacement of one walk is a single chi^2_1 draw) while the Whittle standard error
    assumes independence. Measured over 100 records (16 384 frames, D_d = 2e-16 m^2/s):
    D_hat/D_d = 1.09 +- 0.08 (mean), SD 0.77, median 0.84; pulls (D_hat - D_d)/SE have SD 3.2,
    i.e. the reported SE is ~3x too small. Treat ``drift_diffusion`` as an order of magnitude;
    k and gamma keep calibrated errors (pull SD 0.97 and 0.99 in the same records).

    **Signature and detectability.** Excess at the lowest frequencies (~1/f^2). Detected when
    the drift power at the lowest Fourier frequencies exceeds the trap plateau
    ``2 kT gamma/k^2`` by a few times: ``D_d T^2/pi^2 >~ 10 x 2 kT gamma/k^2``
    (T = record length). Measured (benchmarks/study_diagnose.py; 16 384 frames at 1500 Hz,
    T = 10.9 s, k = 0.01 pN/nm, 1.5 um bead): D_d = 200 nm^2/s found in 10/10 records,
    2 nm^2/s in about half (D_d T^2/pi^2 ~ 10 x the plateau); the detectable D_d falls as
    1/T^2 for longer records."""

    name: ClassVar[str] = "drift"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("drift_diffusion", "m^2/s", 1e18, "nm^2/s", "drift diffusion"),)
    signature: ClassVar[str] = "excess power at the lowest frequencies (~1/f^2)"

    def psd_add(self, f, dt, extras):
        # expected periodogram of a sampled random walk: twice its increment PSD (docstring)
        return 2.0 * drift_psd(f, dt, extras["drift_diffusion"])


class LineNoise(AbstractEffect):
    """A narrow spectral line (mains hum, vibration) at ``frequency`` [Hz] (fixed; diagnose
    finds it as the most significant isolated spike), amplitude ``line_amplitude`` [m].
    Detectable when A^2/2 exceeds ~10 x the PSD at f0 times the frequency resolution."""

    name: ClassVar[str] = "line_noise"
    kind: ClassVar[str] = "additive"
    params: ClassVar = (Param("line_amplitude", "m", 1e9, "nm", "line amplitude"),)
    signature: ClassVar[str] = "isolated spectral spike"
    frequency: float = eqx.field(static=True, default=50.0)
    width: float = eqx.field(static=True, default=0.0)

    def psd_add(self, f, dt, extras):
        return line_psd(f, self.frequency, extras["line_amplitude"], self.width)


class ExposureKernel(AbstractEffect):
    """Trapezoidal exposure: linear rise and fall, each ``rise_fraction`` x W (0-0.5),
    replacing the rectangle (|H|^2 = sinc^2(pi f W (1-r)) sinc^2(pi f W r)). Simulate it with
    ``simulate(..., method="exact", exposure_profile=TrapezoidProfile(r))``.

    Identifiability (measured): with W <= dt the frames stay *exactly* ARMA(1,1) for any
    exposure kernel (same rho = exp(-dt/tau)); the kernel only changes S and B, which k, gamma
    and eps^2 absorb. From a single recording the shape is therefore not detectable (a
    triangular exposure, r = 0.5, on 65 536 camera frames at k = 0.05 pN/nm: likelihood gain
    0.00, yet k biased by +1 to +3.5 SE with an acceptable fit); ``diagnose`` only proposes it
    when the recordings have several exposures. With an exposure series it is detectable when
    the exposure is a sizeable fraction of tau: 4 exposures (0.25-1 dt, 1500 fps,
    k = 0.05 pN/nm, alpha = W/tau up to 1.24, 16 384 frames each) -- a triangle (r = 0.5) was
    ranked first and significant in 10/10 records (p 1e-5 to 2e-3, so near the limit; refit
    adequate with k, gamma within 3 SE in 10/10), r = 0.25 in 8/10; it becomes reliably
    detectable at r ~ 0.5 with this series (longer records or exposures nearer tau
    for smaller r). Detected or not, the rectangular-exposure fit had k or gamma > 3 SE off in
    every one of these records (benchmarks/RESULTS_diagnose.md, section 4);
    at dt >> tau (k = 0.1 pN/nm, 3 x 8192 frames) a triangle was missed in 2/2 records while
    biasing k by ~2.8 SE."""

    name: ClassVar[str] = "exposure_kernel"
    kind: ClassVar[str] = "transfer"
    params: ClassVar = (Param("rise_fraction", "1", 1.0, "", "rise/fall time / W", 0.5),)
    signature: ClassVar[str] = "high-frequency spectral shape unlike sinc^2"

    def transfer(self, f, w, extras):
        r = extras["rise_fraction"]
        # the rectangle's sinc^2 is applied by the model; this is the extra factor
        return (jnp.sinc(f * w * (1.0 - r)) * jnp.sinc(f * w * r) / jnp.sinc(f * w)) ** 2

    def rect_replacement(self, f, w, extras):
        r = extras["rise_fraction"]
        return (jnp.sinc(f * w * (1.0 - r)) * jnp.sinc(f * w * r)) ** 2


class DetectorFilter(AbstractEffect):
    """Photodiode low-pass (Berg-Sorensen et al. 2003): ``f3db`` [Hz] and ``diode_alpha``
    (fraction of instantaneous response), ``|H|^2 = a^2 + (1 - a^2)/(1 + (f/f3db)^2)``, acting
    before the exposure average and the sampling (simulated exactly by
    ``blurtrap.simulate.PhotodiodeFilter``). Signature: high-frequency deficit with the filter
    shape; proposed by ``diagnose`` for fast (>= 10 kHz) sampling. Measured at 100 kHz,
    2^14 samples, 1.5 um bead, k = 0.05 pN/nm: a silicon diode at 1064 nm (f3db = 8 kHz,
    alpha = 0.4) was ranked first and significant in 10/10 records (refit adequate with k,
    gamma within 3 SE in 9/10; the tenth refit had gof p = 2.5e-4), a weak one (30 kHz,
    alpha = 0.6) in 7/10 (the other three were named hydrodynamics with a plausible radius:
    a weak filter and the friction of a large bead look alike at 2^14 samples); 10 seeds
    each, so these are rough rates. No model or simulator error was found behind that failed refit:
    refitting this model to 300 records simulated with the true filter failed the gof at
    diagnose's threshold 0.0083 in 1.0 +- 0.6 % (nominal ~1.1 %), and the model P_d matches an
    independent reference to 2e-5 (benchmarks/RESULTS_diagnose.md, section 4). Its
    high-frequency deficit is also what an unphysically large hydrodynamic radius
    produces; ``diagnose`` rejects that alternative by the Stokes-radius check."""

    name: ClassVar[str] = "detector_filter"
    kind: ClassVar[str] = "transfer"
    params: ClassVar = (
        Param("f3db", "Hz", 1.0, "Hz", "photodiode 3 dB frequency"),
        Param("diode_alpha", "1", 1.0, "", "fast-response fraction", 1.0),
    )
    signature: ClassVar[str] = "high-frequency deficit with a low-pass shape"

    def transfer(self, f, w, extras):
        return photodiode_transfer(f, extras["f3db"], extras["diode_alpha"])

    def transfer_inf(self, extras):
        return extras["diode_alpha"] ** 2


class Hydrodynamics(AbstractEffect):
    """Frequency-dependent friction of a sphere of hydrodynamic radius ``hydro_radius`` [m]
    (Berg-Sorensen & Flyvbjerg 2004, eq. 12; fluid inertia + Basset force; water viscosity and
    density at T, ``blurtrap.physics.water_viscosity`` / ``water_density``). Faxen's law near a
    surface rescales gamma (which stays free: ``gamma`` is the zero-frequency friction), so a
    physical fit has ``hydro_radius <= gamma/(6 pi eta)``; ``diagnose`` rejects candidates that
    violate it by more than 50 %. Simulate it with ``blurtrap.simulate.HydrodynamicFriction``
    (``method="spectral"``).

    Static options: ``distance`` [m] from the bead centre to a surface (default ``None``:
    bulk); with it the frequency dependence is that of Tolic-Norrelykke et al. (2006), eq. D6
    (``blurtrap.physics.complex_friction``), meant for ``distance >~ 1.5 hydro_radius``.
    ``bead_density`` [kg/m^3] (default polystyrene, 1050).

    Signature: relative to the best Lorentzian a high-frequency deficit growing like
    sqrt(f/f_nu), f_nu = nu/(pi R^2) (~130 kHz for R = 1.5 um). Not visible in camera data.
    Detectability (measured, benchmarks/RESULTS_diagnose.md; photodiode, W -> 0, k = 0.05 pN/nm,
    eps = 0.2 nm): the standard model failed in every record for every radius tried (6/6 each
    at R = 1.5, 1.0, 0.5 and 0.25 um, 200 kHz, 2^16 samples = 0.33 s; gof p < 1e-240 at
    1.5 um, a high-frequency candidate at p < 1e-9 at 0.25 um). Naming it correctly is harder
    than detecting it: a 2-parameter photodiode filter mimics the deficit to within a few
    log-likelihood units (expected gap 2.0 per 2^14 samples at 100 kHz, R = 1.5 um). Ranked
    first, refit adequate with k and gamma within 3 SE (6 seeds each, rough rates): R = 1.5 um
    6/6 and R = 1.0 um 6/6 at 200 kHz, 2^16 samples; R = 0.5 um 4/6 and R = 0.25 um 3/6 (the
    others named detector_filter); R = 1.5 um at 100 kHz, 2^14 samples 5/6. So beads of
    R >= 1 um are named reliably with >= 2^16 samples at 200 kHz; smaller beads need longer
    records than that to be named rather than merely detected."""

    name: ClassVar[str] = "hydrodynamics"
    kind: ClassVar[str] = "friction"
    params: ClassVar = (Param("hydro_radius", "m", 1e6, "um", "hydrodynamic radius"),)
    signature: ClassVar[str] = "small high-frequency excess over the Lorentzian"

    distance: float | None = eqx.field(static=True, default=None)
    bead_density: float = eqx.field(static=True, default=POLYSTYRENE_DENSITY)

    def __check_init__(self):
        checks = [("bead_density", self.bead_density, "kg/m^3")]
        if self.distance is not None:
            checks.append(("distance", self.distance, "m (or None: bulk)"))
        for nm, v, unit in checks:
            try:
                ok = not isinstance(v, bool) and 0 < float(v) < float("inf")
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"{nm} must be a finite number > 0 {unit}; got {nm} = {v!r}")

    def lorentzian(self, f, sigma2, tau, temp, extras):
        radius = extras["hydro_radius"]
        eta = water_viscosity(temp)
        rho = water_density(temp)
        k = BOLTZMANN * temp / sigma2
        gamma = tau * k
        d = BOLTZMANN * temp / gamma
        fc = k / (2.0 * jnp.pi * gamma)
        f_nu = eta / rho / (jnp.pi * radius**2)
        m_star = (4.0 / 3.0 * self.bead_density + 2.0 / 3.0 * rho) * jnp.pi * radius**3
        f_m = gamma / (2.0 * jnp.pi * m_star)
        x = 0.0 if self.distance is None else radius / self.distance
        return hydro_lorentzian(f, d, fc, f_nu, f_m, x)


class PowerOffset(AbstractEffect):
    """``k = c (P - P0)``: the stiffness-vs-power line misses the origin by ``power_offset``
    [W] (a power threshold or a calibration offset of the power meter)."""

    name: ClassVar[str] = "power_offset"
    kind: ClassVar[str] = "relation"
    params: ClassVar = (Param("power_offset", "W", 1e3, "mW", "power offset P0"),)
    signature: ClassVar[str] = "k-vs-power line misses the origin"


class LaserHeating(AbstractEffect):
    """Heating ``T = T0 + b P`` at the focus (``heating`` b [K/W]); gamma follows the water
    viscosity eta(T) and kT rises. Signature: curvature in variance-vs-power fits and gamma
    falling with power. Typical b ~ 10-20 K/W at 1064 nm: detectable across >= 4 powers up to
    ~1 W."""

    name: ClassVar[str] = "laser_heating"
    kind: ClassVar[str] = "relation"
    params: ClassVar = (Param("heating", "K/W", 1.0, "K/W", "heating coefficient b"),)
    signature: ClassVar[str] = "gamma falls with laser power"


class Anharmonicity(AbstractEffect):
    """Quartic term in the potential (U = k x^2/2 + k4 x^4/4; simulate with
    ``simulate(..., method="euler", force=quartic_force, force_params=(k, k4))``). Signature:
    non-Gaussian frame histogram (negative excess kurtosis for k4 > 0). Not part of the
    Gaussian (spectral/exact) likelihood: ``diagnose`` tests it with the kurtosis of the frames
    against its correlated-sample standard error, and it cannot be added to a model (no k, gamma
    refit). With beta = k4 kT/k^2 the exact excess kurtosis of the stationary law is -0.094,
    -0.18, -0.27 at beta = 0.02, 0.05, 0.1 (var = 0.95, 0.89, 0.82 kT/k, so the harmonic fit's k
    is 5-22 % high). Measured on 16 384 camera frames (1500 fps, tau = 4 frames, SE of the
    kurtosis ~0.056): beta = 0.1 ranked first and significant in 5/5 records, beta = 0.05 in
    5/5 (5 seeds each); the harmonic fit's k or gamma was > 3 SE off in all 10. The expected
    detection limit is |excess kurtosis| ~ 3 SE, i.e. beta ~ 0.03 at this record length
    (scales as 1/sqrt(N); not measured below beta = 0.05)."""

    name: ClassVar[str] = "anharmonicity"
    kind: ClassVar[str] = "histogram"
    signature: ClassVar[str] = "non-Gaussian position histogram (kurtosis)"


class TimingJitter(AbstractEffect):
    """Irregular frame times. Its spectral signature (extra white noise) is degenerate with
    tracking noise, so ``diagnose`` identifies it from the recording's time stamps (kept with
    ``Recording(..., times=..., allow_irregular=True)``): it is reported when a time stamp
    deviates from the regular grid by more than ``timing_tolerance`` (default 1e-3 frame
    intervals). Measured (benchmarks/study_diagnose.py, 16 384 frames): jitter std 5 % of dt
    found in 5/5 records, 0.02 % of dt (largest deviation ~0.08 %, below the tolerance) in
    0/5; i.i.d. jitter is flagged once its std exceeds ~2.5e-4 dt."""

    name: ClassVar[str] = "timing_jitter"
    kind: ClassVar[str] = "timestamps"
    signature: ClassVar[str] = "uneven time stamps"


EFFECTS: dict[str, type[AbstractEffect]] = {
    cls.name: cls
    for cls in (MotionBlur, Aliasing, TrackingNoise, Drift, ExposureKernel, DetectorFilter,
                Hydrodynamics, Anharmonicity, LaserHeating, PowerOffset, LineNoise,
                TimingJitter)
}


def make_effect(effect, **config) -> AbstractEffect:
    """An effect instance from a canonical name (or pass an instance through)."""
    if isinstance(effect, AbstractEffect):
        return effect
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; canonical names: {sorted(EFFECTS)}")
    return EFFECTS[effect](**config)
