r"""Power spectra and autocovariance of blurred, sampled, noisy trap positions.

All spectra are two-sided: the continuous ones integrate to the variance over
f in (-inf, inf), the discrete ones over (-fs/2, fs/2).

The exact closed forms (DESIGN item 5) follow from the frame autocovariance
``C(0) = sigma2 S(alpha) + eps2`` and ``C(n) = sigma2 B(alpha) rho^n`` (n >= 1) with
``B = 2 (cosh(alpha) - 1)/alpha^2`` and ``rho = exp(-dt/tau)``.
"""

from __future__ import annotations

import jax.numpy as jnp

from ._blur import _blur_factor, _rho_b, _rho_b_minus_s
from ._checks import (
    check_count,
    check_exposure_le_interval,
    check_finite,
    check_integer,
    check_nonnegative,
    check_positive,
    is_concrete,
)
from ._constants import BOLTZMANN, DEFAULT_TEMPERATURE


def _check_trap(k, gamma, temperature):
    k = check_positive("k", k, "N/m", what="trap stiffness")
    gamma = check_positive("gamma", gamma, "N s/m", what="friction coefficient")
    t = check_positive("temperature", temperature, "K")
    return k, gamma, t


def lorentzian(f, k, gamma, temperature=DEFAULT_TEMPERATURE):
    r"""Continuous two-sided PSD of the true position (paper eq. 14 in Hz):

    $$P(f) = \frac{2\sigma^2\tau}{1 + (2\pi f\tau)^2},\quad \sigma^2 = k_BT/k,\ \tau = \gamma/k.$$

    **Arguments:** `f` [Hz]; `k` [N/m]; `gamma` [N s/m]; `temperature` [K].
    **Returns:** P(f) [m^2/Hz].
    """
    f = check_finite("f", f, "Hz")
    k, gamma, t = _check_trap(k, gamma, temperature)
    sigma2 = BOLTZMANN * t / k
    tau = gamma / k
    return 2.0 * sigma2 * tau / (1.0 + (2.0 * jnp.pi * f * tau) ** 2)


def transfer_rect(f, exposure):
    r"""``|H(f)|^2 = sinc^2(pi f W)`` of a rectangular exposure of length W [s].

    **Raises:** ``ValueError`` if a concrete `f` [Hz] is not finite or `exposure` [s] is not
    finite and > 0.
    """
    f = check_finite("f", f, "Hz")
    w = check_positive("exposure", exposure, "s", what="exposure time W")
    return jnp.sinc(f * w) ** 2


def _psd_coeffs(sigma2, tau, w, dt, eps2):
    """Frequency-independent coefficients of the closed-form discrete PSD (see
    ``_psd_discrete``); computing them once per recording keeps per-frequency work tiny."""
    a = w / tau
    r = dt / tau
    one_m_rho = -jnp.expm1(-r)
    rho = jnp.exp(-r)
    sa = _blur_factor(a)
    rho_b = _rho_b(a, r)
    c_a = sigma2 * one_m_rho * (sa * one_m_rho + 2.0 * rho_b)
    c_b = 4.0 * sigma2 * _rho_b_minus_s(a, r, sa, rho_b)
    return dt, one_m_rho, rho, c_a, c_b, eps2


def _psd_from_coeffs(f, coeffs):
    dt, one_m_rho, rho, c_a, c_b, eps2 = coeffs
    s2 = jnp.sin(jnp.pi * f * dt) ** 2
    return dt * ((c_a - s2 * c_b) / (one_m_rho**2 + 4.0 * rho * s2) + eps2)


def _expected_block_periodogram(f, block_len, sigma2, tau, w, dt, eps2, *, s2=None):
    r"""Exact expectation of the periodogram of a block of M frames at Fourier frequencies
    f = j/(M dt), j = 1..M/2 (block mean removed, which only affects j = 0):

    E[I_j] = dt [C(0) + 2 Re sum_{n=1}^{M-1} (1 - n/M) C(n) e^{-i theta n}],  theta = 2 pi f dt,

    summed in closed form for C(n) = C(1) rho^(n-1). The geometric sums in q = rho e^{-i theta}
    (with q^M = rho^M at Fourier frequencies) have a real part that is rational in
    s = sin^2(theta/2): with cos theta = 1 - 2 s, |1 - q|^2 = D = (1-rho)^2 + 4 rho s and
    R = rho^(M-1),

    Re sum_{n<M} (1 - n/M) rho^(n-1) e^{-i theta n} = [N_1 - N_2/(M D)] / D,
    N_1 = (1-rho)(1-R) - 2 s (1 + R rho),
    N_2 = Delta (1-rho)^2 - 2 [M R (1-rho)(1 + 3 rho) + Delta (1 + rho^2)] s - 8 M R rho^2 s^2,
    Delta = (1 - R) - (M-1) R (1-rho)  (>= 0)

    (the real part of the complex closed form, expanded and arranged so that no two large
    terms cancel; no complex arithmetic, and no trigonometric function when ``s2`` =
    sin^2(pi f dt) is given). Unlike P_d(f) it contains the Fejer-kernel leakage of a finite
    block exactly; for M -> inf it tends to P_d(f).
    """
    a = w / tau
    r = dt / tau
    c0 = sigma2 * _blur_factor(a) + eps2
    c1 = sigma2 * _rho_b(a, r)
    m = block_len
    s = jnp.sin(jnp.pi * f * dt) ** 2 if s2 is None else s2
    rho = jnp.exp(-r)
    omr = -jnp.expm1(-r)
    rm1 = jnp.exp(-r * (m - 1.0))  # R = rho^(M-1), no 0/0 when rho underflows (dt >> tau)
    omrm1 = -jnp.expm1(-r * (m - 1.0))  # 1 - R
    mr = m * rm1
    delta = omrm1 - (m - 1.0) * rm1 * omr
    d = omr * omr + 4.0 * rho * s
    n1 = omr * omrm1 - 2.0 * (1.0 + rm1 * rho) * s
    n2 = (delta * (omr * omr)
          - 2.0 * (mr * omr * (1.0 + 3.0 * rho) + delta * (1.0 + rho * rho)) * s
          - 8.0 * mr * rho * rho * s * s)
    tot = (n1 - n2 / (m * d)) / d
    return dt * (c0 + 2.0 * c1 * tot)


def _psd_discrete(f, sigma2, tau, w, dt, eps2):
    """Closed-form aliased, blurred, noisy discrete two-sided PSD, no input checks.

    P_d/dt = sigma2 [(1-rho)(S(1-rho) + 2 rho B) - 4 s^2 rho (B - S)] / [(1-rho)^2 + 4 rho s^2]
             + eps2,   s = sin(pi f dt),
    an algebraically exact rearrangement of DESIGN item 5 with no cancellation for small
    alpha, small dt/tau or large alpha.
    """
    return _psd_from_coeffs(f, _psd_coeffs(sigma2, tau, w, dt, eps2))


def _psd_blurred(f, sigma2, tau, w):
    return 2.0 * sigma2 * tau / (1.0 + (2.0 * jnp.pi * f * tau) ** 2) * jnp.sinc(f * w) ** 2


def _psd_alias_sum(f, sigma2, tau, w, dt, eps2, n_alias: int):
    n = jnp.arange(-n_alias, n_alias + 1, dtype=f.dtype)
    shape = jnp.broadcast_shapes(f.shape, sigma2.shape, tau.shape, w.shape, dt.shape)
    ff = jnp.broadcast_to(f, shape)[..., None] + n / jnp.broadcast_to(dt, shape)[..., None]
    terms = _psd_blurred(ff, sigma2[..., None], tau[..., None], w[..., None])
    return jnp.sum(terms, axis=-1) + eps2 * dt


def psd_measured(
    f,
    k,
    gamma,
    exposure,
    temperature=DEFAULT_TEMPERATURE,
    frame_interval=None,
    tracking_var=0.0,
    n_alias=None,
):
    r"""Two-sided PSD of the measured (blurred, optionally sampled) position.

    - ``frame_interval=None``: continuous blurred PSD ``P(f) sinc^2(pi f W)`` (paper eq. 19).
      A white tracking noise has no continuous PSD, so ``tracking_var`` must then be 0.
    - ``frame_interval=dt`` and ``n_alias=None``: the exact aliased, blurred PSD in closed form
      (infinite alias sum, DESIGN item 5) plus ``eps2 * dt``.
    - ``frame_interval=dt`` and ``n_alias=N``: the paper's truncated sum (eq. 20) over
      ``|n| <= N`` plus ``eps2 * dt``.

    **Arguments:** `f` [Hz]; `k` [N/m]; `gamma` [N s/m]; `exposure` W [s]; `temperature` [K];
    `frame_interval` dt [s] (>= W); `tracking_var` eps^2 [m^2]; `n_alias` int or None.

    **Returns:** PSD [m^2/Hz]; the discrete one integrates to ``C(0)`` over (-fs/2, fs/2).
    """
    f = check_finite("f", f, "Hz")
    k, gamma, t = _check_trap(k, gamma, temperature)
    w = check_positive("exposure", exposure, "s", what="exposure time W")
    eps2 = check_nonnegative("tracking_var", tracking_var, "m^2", what="tracking-error variance")
    sigma2 = BOLTZMANN * t / k
    tau = gamma / k
    if frame_interval is None:
        if n_alias is not None:
            raise ValueError("n_alias needs frame_interval (aliasing is a property of sampling)")
        if not is_concrete(eps2) or jnp.any(eps2 != 0):
            raise ValueError(
                "tracking_var needs frame_interval: white tracking noise has no continuous "
                "PSD (its discrete PSD is tracking_var * frame_interval)"
            )
        return _psd_blurred(f, sigma2, tau, w)
    dt = check_positive("frame_interval", frame_interval, "s", what="frame interval dt")
    w = check_exposure_le_interval(w, dt)
    if n_alias is None:
        return _psd_discrete(f, sigma2, tau, w, dt, eps2)
    n_alias = check_count("n_alias", n_alias, 0, allowed=" or None")
    arrs = jnp.broadcast_arrays(f, sigma2, tau, w, dt, eps2)
    return _psd_alias_sum(*arrs, n_alias)  # pyright: ignore[reportCallIssue]  # arrs: 6 arrays


def _autocovariance(n, sigma2, tau, w, dt, eps2):
    a = w / tau
    r = dt / tau
    n = jnp.abs(n)
    c0 = sigma2 * _blur_factor(a) + eps2
    nm1 = jnp.maximum(n - 1, 0)
    cn = sigma2 * _rho_b(a, r) * jnp.exp(-r * nm1)
    return jnp.where(n == 0, c0, cn)


def frame_autocovariance(
    lag, k, gamma, exposure, frame_interval, temperature=DEFAULT_TEMPERATURE, tracking_var=0.0
):
    r"""Autocovariance ``C(n)`` of frames that start every dt and average over W <= dt.

    ``C(0) = sigma2 S(alpha) + eps2`` and ``C(n) = sigma2 B(alpha) rho^|n|`` for n != 0,
    with ``B = (sinh(alpha/2)/(alpha/2))^2``, ``rho = exp(-dt/tau)`` (computed overflow-free
    as ``((1-e^-alpha)/alpha)^2 exp(alpha - |n| dt/tau)``).

    **Arguments:** `lag` n (integer, any sign); `k` [N/m]; `gamma` [N s/m]; `exposure` [s];
    `frame_interval` [s]; `temperature` [K]; `tracking_var` [m^2].
    **Returns:** C(n) [m^2].
    **Raises:** ``ValueError`` for a lag that is not a whole number, or parameters out of range.
    """
    k, gamma, t = _check_trap(k, gamma, temperature)
    w = check_positive("exposure", exposure, "s", what="exposure time W")
    dt = check_positive("frame_interval", frame_interval, "s", what="frame interval dt")
    w = check_exposure_le_interval(w, dt)
    eps2 = check_nonnegative("tracking_var", tracking_var, "m^2", what="tracking-error variance")
    n = check_integer("lag", lag, what="frame lag")
    return _autocovariance(n, BOLTZMANN * t / k, gamma / k, w, dt, eps2)


def _sample_variance_var(n_frames, sigma2, tau, w, dt, eps2):
    """Exact variance of the (known-mean) sample variance of N Gaussian frames:
    var(s^2) = (2/N^2) sum_{|n|<N} (N - |n|) C(n)^2, summed in closed form.
    """
    a = w / tau
    r = dt / tau
    c0 = sigma2 * _blur_factor(a) + eps2
    c1 = sigma2 * _rho_b(a, r)  # C(1); C(n) = c1 q^{(n-1)/2} with q = rho^2
    nn = jnp.asarray(n_frames, dtype=c0.dtype)
    # sum_{n=1}^{N-1} (N - n) q^{n-1} = [N (1-q) - (1 - q^N)] / (1-q)^2
    one_m_q = -jnp.expm1(-2.0 * r)
    one_m_qn = -jnp.expm1(-2.0 * r * nn)
    geo = (nn * one_m_q - one_m_qn) / one_m_q**2
    # fallback for q -> 1 (r -> 0): sum = N(N-1)/2 (only when r*N is tiny)
    geo = jnp.where(2.0 * r * nn < 1e-6, nn * (nn - 1.0) / 2.0, geo)
    return (2.0 / nn**2) * (nn * c0**2 + 2.0 * c1**2 * geo)


def sample_variance_se(
    n_frames, k, gamma, exposure, frame_interval, temperature=DEFAULT_TEMPERATURE, tracking_var=0.0
):
    r"""Standard error of the sample variance of N correlated frames (DESIGN item 10).

    ``var(s^2) = (2/N^2) sum_{|n|<N} (N-|n|) C(n)^2`` (Gaussian frames, known mean), which
    tends to ``(2/N) sum_n C(n)^2`` for long records and to ``sqrt(2/N) C(0)`` when frames are
    independent.

    **Returns:** standard error of s^2 [m^2].
    """
    k, gamma, t = _check_trap(k, gamma, temperature)
    w = check_positive("exposure", exposure, "s", what="exposure time W")
    dt = check_positive("frame_interval", frame_interval, "s", what="frame interval dt")
    w = check_exposure_le_interval(w, dt)
    eps2 = check_nonnegative("tracking_var", tracking_var, "m^2", what="tracking-error variance")
    n = check_positive("n_frames", n_frames, what="number of frames")
    return jnp.sqrt(_sample_variance_var(n, BOLTZMANN * t / k, gamma / k, w, dt, eps2))


def discrete_psd_unchecked(f, sigma2, tau, exposure, frame_interval, tracking_var):
    """The closed-form discrete PSD [m^2/Hz] in the trap's natural parameters (sigma2 [m^2],
    tau [s]) without input checks: for optimisers and gradients, whose trial points may be
    extreme (a checked function would raise there instead of letting a line search step back).
    """
    return _psd_discrete(f, sigma2, tau, exposure, frame_interval, tracking_var)


def autocovariance_unchecked(lag, sigma2, tau, exposure, frame_interval, tracking_var):
    """The frame autocovariance C(lag) [m^2] without input checks (see
    :func:`discrete_psd_unchecked`)."""
    return _autocovariance(lag, sigma2, tau, exposure, frame_interval, tracking_var)


# Unchecked kernels shared with the estimators (see :func:`discrete_psd_unchecked`); public
# under these names, in the trap's natural parameters (sigma2 [m^2], tau [s]).
psd_coeffs_unchecked = _psd_coeffs  # frequency-independent coefficients of the discrete PSD
expected_block_periodogram_unchecked = _expected_block_periodogram  # E[periodogram of M frames]
sample_variance_var_unchecked = _sample_variance_var  # var(s^2) of N frames (DESIGN item 10)
