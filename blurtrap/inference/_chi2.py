"""The chi^2 survival function on the host (no JAX compilation), for goodness-of-fit
p-values."""

from __future__ import annotations

import math


def chi2_sf(x, dof) -> float:
    """Survival function P(chi^2_dof > x) for scalars, on the host (no JAX compilation):
    the regularised upper incomplete gamma Q(dof/2, x/2) by its series (x < a + 1) or
    continued fraction (Numerical Recipes 6.2), relative accuracy ~1e-14."""
    a, z = 0.5 * float(dof), 0.5 * float(x)
    if not (a > 0 and math.isfinite(a)) or math.isnan(z):
        return math.nan
    if z <= 0:
        return 1.0
    if math.isinf(z):
        return 0.0
    log_pref = -z + a * math.log(z) - math.lgamma(a)
    if z < a + 1.0:  # P(a, z) by its series; Q = 1 - P is not small here
        term = total = 1.0 / a
        n = 0
        while abs(term) > 1e-17 * abs(total) and n < 100000:
            n += 1
            term *= z / (a + n)
            total += term
        return max(0.0, 1.0 - total * math.exp(log_pref))
    # Q(a, z) by the continued fraction (modified Lentz)
    tiny = 1e-300
    b = z + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-16:
            break
    return math.exp(log_pref) * h


def _betacf(a: float, b: float, x: float) -> float:
    """The continued fraction of the regularised incomplete beta function (Numerical
    Recipes 6.4, modified Lentz)."""
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (tiny if abs(d) < tiny else d)
    h = d
    for m in range(1, 100000):
        m2 = 2 * m
        for aa in (m * (b - m) * x / ((qam + m2) * (a + m2)),
                   -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))):
            d = 1.0 + aa * d
            d = 1.0 / (tiny if abs(d) < tiny else d)
            c = 1.0 + aa / c
            c = tiny if abs(c) < tiny else c
            h *= d * c
        if abs(d * c - 1.0) < 1e-16:
            break
    return h


def betainc(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b) for scalars, on the host."""
    if not (a > 0 and b > 0) or math.isnan(x):
        return math.nan
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x)
                 + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _betacf(a, b, x) / a
    return 1.0 - math.exp(log_front) * _betacf(b, a, 1.0 - x) / b


def f_sf(x, d1, d2) -> float:
    """Survival function P(F_{d1, d2} > x) of the F distribution, on the host:
    ``I_{d2 / (d2 + d1 x)}(d2 / 2, d1 / 2)``."""
    x = float(x)
    if math.isnan(x):
        return math.nan
    if x <= 0.0:
        return 1.0
    if math.isinf(x):
        return 0.0
    return betainc(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * x))
