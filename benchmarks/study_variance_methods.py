"""Monte Carlo study of variance_vs_exposure and variance_vs_power (paper sections 6.2-6.3):
bias, SD/SE and 95 % coverage of k, gamma and eps^2, with data generated independently of
blurtrap's simulator.

    python benchmarks/study_variance_methods.py [--datasets 100] [--designs vve vvp]
                                                [--k 4e-5] [--vvp-w 2e-3] [--seed 0]

Generator (numpy only): the frames of a blurred, sampled, noisy harmonic trap are a
stationary Gaussian sequence with autocovariance ``C(0) = sigma2 S(alpha) + eps2`` and
``C(n) = sigma2 B(alpha) rho^n`` (n >= 1), ``B = 2 (cosh(alpha) - 1)/alpha^2``,
``rho = exp(-dt/tau)`` (DESIGN item 5). Frames are drawn exactly by circulant embedding:
the covariance extended to a circulant of size 2N has eigenvalues ``FFT(c)``; with complex
white noise z, ``FFT(sqrt(lambda/2N) z)`` has real and imaginary parts that are two
independent exact draws (up to rho^N, here < 1e-10).

Designs (1500 fps camera, eps = 2 nm, 32 768 frames per recording, 3.06 um bead in water):
  vve: one trap (k = --k), exposures W/dt = 0.1, 0.25, 0.5, 0.75, 1;
  vvp: four powers 0.1-0.4 W with k = c P (c = 1e-4 N/m/W), one exposure W = --vvp-w
       (frame interval max(W, 1/1500 s); 2 ms is the demo's).
Results: benchmarks/RESULTS_variance_methods.md.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

BOLTZMANN = 1.380649e-23
TEMP = 295.0
KT = BOLTZMANN * TEMP
GAMMA = 6 * math.pi * 0.00095 * 1.53e-6
DT = 1 / 1500
EPS = 2e-9
N = 32768


# ---- independent generator ---------------------------------------------------------------
def _s_b(alpha):
    """S(alpha) and B(alpha) in numpy (series below 1e-3; stable forms above)."""
    a = float(alpha)
    if a < 1e-3:
        s = 1 - a / 3 + a * a / 12 - a**3 / 60
    else:
        s = 2 / a - 2 * (-math.expm1(-a)) / a**2
    b = 1.0 if a == 0 else (math.sinh(a / 2) / (a / 2)) ** 2
    return s, b


def autocovariance(k, gamma, w, dt, eps2, n):
    """C(0..n-1) of the frames [m^2]."""
    sigma2, tau = KT / k, gamma / k
    s, b = _s_b(w / tau)
    c = sigma2 * b * np.exp(-np.arange(n) * dt / tau)
    c[0] = sigma2 * s + eps2
    return c


def draw_pair(c, rng):
    """Two independent exact Gaussian sequences with autocovariance ``c`` (length N)."""
    n = c.size
    ext = np.concatenate([c, [0.0], c[:0:-1]])  # circulant of size 2N (c[N] ~ 0)
    lam = np.fft.fft(ext).real
    if lam.min() < -1e-9 * lam.max():  # pragma: no cover - not for these parameters
        raise RuntimeError("circulant embedding not non-negative")
    lam = np.clip(lam, 0.0, None)
    z = rng.standard_normal(ext.size) + 1j * rng.standard_normal(ext.size)
    y = np.fft.fft(np.sqrt(lam / ext.size) * z)
    return y.real[:n], y.imag[:n]


class Frames:
    """Hands out exact draws for a given autocovariance, two per FFT."""

    def __init__(self, rng):
        self.rng = rng
        self.spare = {}

    def __call__(self, k, gamma, w, dt, eps2, n):
        key = (k, gamma, w, dt, eps2, n)
        if self.spare.get(key):
            return self.spare[key].pop()
        a, b = draw_pair(autocovariance(k, gamma, w, dt, eps2, n), self.rng)
        self.spare.setdefault(key, []).append(b)
        return a


# ---- designs -----------------------------------------------------------------------------
def design_vve(k):
    ws = DT * np.array([0.1, 0.25, 0.5, 0.75, 1.0])
    return [dict(k=k, w=float(w), dt=DT, power=None) for w in ws], {
        "k": k, "gamma": GAMMA, "tracking_var": EPS**2}


def design_vvp(w=2e-3, c=1e-4, powers=(0.1, 0.2, 0.3, 0.4)):
    return [dict(k=c * p, w=w, dt=max(w, DT), power=p) for p in powers], {
        "c": c, "gamma": GAMMA, "tracking_var": EPS**2}


METHOD = {"vve": "variance_vs_exposure", "vvp": "variance_vs_power"}


def run(design, n_sets, seed, k, vvp_w, log):
    import blurtrap as bt

    recs_spec, truth = design_vve(k) if design == "vve" else design_vvp(vvp_w)
    gen = Frames(np.random.default_rng(seed))
    names = list(truth)
    est, err, lo, hi, ratio, fails, branch = [], [], [], [], [], 0, 0
    t0 = time.perf_counter()
    for i in range(n_sets):
        recs = []
        for sp in recs_spec:
            x = gen(sp["k"], GAMMA, sp["w"], sp["dt"], EPS**2, N)
            recs.append(bt.Recording(x, frame_interval=sp["dt"], exposure=sp["w"],
                                     temperature=TEMP, laser_power=sp["power"]))
        try:
            res = bt.calibrate(recs, method=METHOD[design])
        except Exception as e:  # noqa: BLE001 - counted and reported
            fails += 1
            log(f"  dataset {i}: {type(e).__name__}: {e}")
            continue
        p = res.params
        est.append([p[n] for n in names])
        err.append([res.errors[res.param_names.index(n)] for n in names])
        iv = getattr(res, "intervals", None) or res.extras.get("intervals", {})
        lo.append([iv.get(n, (np.nan, np.nan))[0] for n in names])
        hi.append([iv.get(n, (np.nan, np.nan))[1] for n in names])
        ratio.append(res.extras.get("joint_se_ratio", np.nan))
        branch += any("second branch" in note for note in res.notes)
        if (i + 1) % 25 == 0:
            log(f"  {design}: {i + 1}/{n_sets} datasets ({time.perf_counter() - t0:.0f} s)")
    est, err, lo, hi = map(np.asarray, (est, err, lo, hi))
    tv = np.array([truth[n] for n in names])
    rows = []
    for j, n in enumerate(names):
        e, s = est[:, j], err[:, j]
        m = len(e)
        bias = 100 * (e.mean() / tv[j] - 1)
        bias_se = 100 * e.std(ddof=1) / math.sqrt(m) / tv[j]
        med = 100 * (np.median(e) / tv[j] - 1)
        sd_se = e.std(ddof=1) / np.sqrt(np.mean(s**2))
        wald = np.mean(np.abs(e - tv[j]) <= 1.96 * s)
        # profile interval coverage; an end that could not be found (NaN) counts as a miss
        has = ~np.isnan(lo[:, j]).all()
        cov_iv = np.mean((lo[:, j] <= tv[j]) & (tv[j] <= hi[:, j])) if has else float("nan")
        n_nan = int(np.sum(np.isnan(lo[:, j]) | np.isnan(hi[:, j]))) if has else 0
        at0 = (lo[:, j] == 0) & (n != "tracking_var")  # eps^2's bound 0 is a legitimate end
        n_inf = int(np.sum(np.isinf(hi[:, j]) | at0)) if has else 0
        rows.append((n, m, bias, bias_se, med, sd_se, wald, cov_iv, n_nan, n_inf))
    ratio = np.asarray(ratio, dtype=float)
    med = float(np.nanmedian(ratio)) if np.isfinite(ratio).any() else float("nan")
    return rows, fails, med, branch


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--datasets", type=int, default=100)
    ap.add_argument("--designs", nargs="+", default=["vve", "vvp"], choices=["vve", "vvp"])
    ap.add_argument("--k", type=float, default=4e-5, help="stiffness of the vve design [N/m]")
    ap.add_argument("--vvp-w", type=float, default=2e-3, help="exposure of the vvp design [s]")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)

    import blurtrap as bt

    bt.enable_x64()
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    from _machine import cpu_model

    def log(msg):
        print(msg, file=sys.stderr, flush=True)

    print(f"# {a.datasets} datasets per design, {N} frames per recording, seed {a.seed}; "
          f"CPU: {cpu_model()}; blurtrap from {bt.__file__}")
    for d in a.designs:
        t0 = time.perf_counter()
        rows, fails, ratio, branch = run(d, a.datasets, a.seed, a.k, a.vvp_w, log)
        desc = (f"vve: k = {a.k:g} N/m, W/dt = 0.1..1" if d == "vve"
                else f"vvp: c = 1e-4 N/m/W, P = 0.1..0.4 W, W = {a.vvp_w * 1e3:.4g} ms, "
                f"dt = {max(a.vvp_w, DT) * 1e3:.4g} ms")
        print(f"\n## {desc} ({time.perf_counter() - t0:.0f} s, {fails} failed fits, "
              f"median joint-likelihood SE ratio for k: {ratio:.3g}; intervals spanning a "
              f"second branch: {branch})")
        print("| param | n | bias % (+- SE) | median bias % | SD/SE | Wald 95% cover | "
              "profile 95% cover | NaN ends | open ends (0 or inf) |")
        print("|---|---|---|---|---|---|---|---|---|")
        for n, m, b, bse, med, sdse, wald, civ, n_nan, n_inf in rows:
            print(f"| {n} | {m} | {b:+.2f} +- {bse:.2f} | {med:+.2f} | {sdse:.2f} | "
                  f"{100 * wald:.0f} % | {100 * civ:.0f} % | {n_nan} | {n_inf} |")


if __name__ == "__main__":
    main()
