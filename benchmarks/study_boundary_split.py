"""Where the bias of short records at the boundary eps^2 = 0 comes from (not a test).

``study_boundary.py``'s exact regime (4096 camera frames, W = 0.1 dt, eps = 2 nm, k = 0.05
pN/nm, circulant-embedding frames: not blurtrap's simulator) found k +5 % and gamma +10 %.
Here each dataset is fitted twice with the exact likelihood: ``calibrate(likelihood="exact")``
(eps^2 >= 0, the reported estimate) and the *unconstrained* maximum-likelihood estimate
(eps^2 free to go below 0 as long as the frames' covariance stays positive: the fit of
eps^2 + offset). The difference is the bound's share of the bias, the rest the estimator's own
small-sample bias, which is compared with its first-order (Cox-Snell) prediction from the
Whittle cumulants at the truth: ``b = -1/2 I^-1 sum_j G_j (q_j + h_j)`` with ``G_j`` the
gradient of log S(f_j), ``q_j = G_j' I^-1 G_j``, ``h_j = tr(I^-1 d2 log S(f_j))`` and
``I = sum_j G_j G_j'`` (periodogram ordinates exponential with mean S).

Run: ``python benchmarks/study_boundary_split.py [--n 1000] [--seed 20261125]`` (~2 min on
one core).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from study_boundary import DT, EPS2, GAMMA, NAMES, TRUE, CirculantSampler, W, autocovariance
from study_boundary import K as K_TRUE
from study_boundary import T as TEMP

N_FRAMES = 4096


def _shifted(p, a):
    from blurtrap.inference._problems import exact_nll

    args, off = a
    return exact_nll(p - off, args)


def fits(n, seed):
    """(constrained values (n, 3), unconstrained values (n, 3), eps^2 at its bound (n,))."""
    import jax.numpy as jnp

    import blurtrap as bt
    from blurtrap.inference._fit import fit_ml_fd_newton
    from blurtrap.inference._models import get_model
    from blurtrap.inference._problems import make_exact_args, make_layout

    bt.enable_x64()
    warnings.simplefilter("ignore")
    sampler = CirculantSampler(autocovariance(K_TRUE, GAMMA, W, DT, EPS2, N_FRAMES))
    con, unc, bound = np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.zeros(n, bool)
    off = jnp.array([0.0, 0.0, 6.0 * EPS2])
    for i, y in enumerate(sampler.draw(np.random.default_rng(seed), n)):
        rec = bt.Recording(y, frame_interval=DT, exposure=W, temperature=TEMP)
        try:  # a refusal is counted (NaN), never dropped
            fit = bt.calibrate(rec, likelihood="exact")
        except bt.FitError:
            continue
        con[i] = [fit.params[nm] for nm in NAMES]
        bound[i] = "tracking_var" in fit.at_bounds
        a = make_exact_args([rec], make_layout([rec], "shared", True), get_model("standard"))
        out = fit_ml_fd_newton(_shifted, jnp.asarray(con[i]) + off, (a, off))
        if bool(out.success):
            unc[i] = np.asarray(out.value - off)
    return con, unc, bound


def cox_snell():
    """First-order bias (relative) of the unconstrained Whittle estimate at the truth."""
    import jax
    import jax.numpy as jnp

    import blurtrap as bt
    from blurtrap.inference._models import get_model
    from blurtrap.inference._problems import make_layout, spectral_model_psd
    from blurtrap.inference._spectral import _spectral_args

    rec = bt.Recording(np.random.default_rng(0).normal(size=N_FRAMES) * 1e-8,
                       frame_interval=DT, exposure=W, temperature=TEMP)
    a = _spectral_args([rec], make_layout([rec], "shared", True), get_model("standard"), 1,
                       None)
    p = jnp.array([TRUE[nm] for nm in NAMES])
    w = np.asarray(a.weight)[0]

    def log_s(q):
        return jnp.log(spectral_model_psd(q, a))[0]

    g = np.asarray(jax.jacfwd(log_s)(p))
    h = np.asarray(jax.jacfwd(jax.jacfwd(log_s))(p))
    info_inv = np.linalg.inv(g.T @ (w[:, None] * g))
    q = np.einsum("jt,tu,ju->j", g, info_inv, g)
    tr = np.einsum("tu,jtu->j", info_inv, h)
    return -0.5 * info_inv @ (g.T @ (w * (q + tr))) / np.asarray(p)


def report(con, unc, bound):
    ok = np.isfinite(con[:, 0]) & np.isfinite(unc[:, 0])
    m = int(ok.sum())
    print(f"{m} of {len(ok)} datasets with both fits; eps^2 at its bound in "
          f"{100 * bound[ok].mean():.1f} %, unconstrained eps^2 < 0 in "
          f"{100 * (unc[ok, 2] < 0).mean():.1f} %")
    pred = cox_snell()
    print("| parameter | constrained bias % (MC SE) | unconstrained bias % (MC SE) | "
          "first-order prediction % | constrained RMSE % | unconstrained RMSE % | "
          "constrained bias, interior / at the bound % |")
    print("|---|---|---|---|---|---|---|")
    for j, nm in enumerate(NAMES):
        rc, ru = con[ok, j] / TRUE[nm] - 1, unc[ok, j] / TRUE[nm] - 1
        se_c, se_u = rc.std() / np.sqrt(m), ru.std() / np.sqrt(m)
        rms_c, rms_u = np.sqrt(np.mean(rc ** 2)), np.sqrt(np.mean(ru ** 2))
        print(f"| {nm} | {100 * rc.mean():+.2f} ({100 * se_c:.2f}) | {100 * ru.mean():+.2f} "
              f"({100 * se_u:.2f}) | {100 * pred[j]:+.2f} | {100 * rms_c:.1f} | "
              f"{100 * rms_u:.1f} | {100 * rc[~bound[ok]].mean():+.1f} / "
              f"{100 * rc[bound[ok]].mean():+.1f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=20261125)
    a = ap.parse_args(argv)
    t0 = time.time()
    con, unc, bound = fits(a.n, a.seed)
    print(f"{a.n} datasets of {N_FRAMES} frames, seed {a.seed}, {time.time() - t0:.0f} s")
    report(con, unc, bound)


if __name__ == "__main__":
    main()
