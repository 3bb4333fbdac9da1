"""Where the 4096-frame exact-likelihood bias at the eps^2 = 0 boundary comes from (issue 18):
the same datasets fitted three ways.

- ``con``: ``bt.calibrate(..., likelihood="exact")`` (eps^2 >= 0, the package's estimate);
- ``unc``: the exact likelihood with eps^2 free to go below 0 (shifted positive parameter);
- ``cs``: ``unc`` minus its Cox-Snell first-order bias, computed from the Whittle cumulants of
  the model spectrum at the estimate (autodiff: b = F^-1 A F^-1 with
  A_ijk = 1/2 sum_f w (u_ij u_k - u_ik u_j - u_jk u_i - u_i u_j u_k), u = log S).

Frames from study_boundary's numpy circulant-embedding sampler (not blurtrap's simulator).
Usage: ``python benchmarks/study_boundary_bias.py N_DATASETS [N_FRAMES] [REGIME] [SEED]``
(defaults 300, 4096, exact, 7). Prints bias, MC SE, median, Wald coverage with the Whittle
Fisher SE at the estimate, and SD/SE.

Session 12, parametric-bootstrap bias correction (exact likelihood, 4096 frames):
``python benchmarks/study_boundary_bias.py boot N B OUT.npz [--seed 7] [--intervals M]
[--iterate] [--max-iter 20]`` fits N datasets, simulates B recordings from each fit with
blurtrap's exact frame sampler (key ``fold_in(PRNGKey(seed), i)``), refits them with the same
exact likelihood (vmapped Newton, :mod:`blurtrap.inference._bias`) and saves the refits' mean;
``python benchmarks/study_boundary_bias.py boot-report OUT.npz`` prints bias and SD of the
uncorrected and corrected estimates (additive ``2 fit - mean``, ratio ``fit^2 / mean``, log
scale, and, with ``--iterate``, ``fit - b(corrected)``) and whether the corrected values lie
inside the profile intervals of the first M datasets.
"""
import argparse
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
import jax
import jax.numpy as jnp
import study_boundary as sb

import blurtrap as bt
from blurtrap.inference._fit import fit_ml
from blurtrap.inference._models import get_model
from blurtrap.inference._problems import exact_nll, make_exact_args, make_layout, spectral_model_psd, spectral_nll
from blurtrap.inference._spectral import _spectral_args

bt.enable_x64()
warnings.simplefilter("ignore")


def three_ways(argv):
    """Session 10: constrained, unconstrained and Cox-Snell (module docstring)."""
    n = int(argv[0]) if argv else 300
    nf = int(argv[1]) if len(argv) > 1 else 4096
    regime = argv[2] if len(argv) > 2 else "exact"
    def shifted(p, a):
        args, off = a
        return (exact_nll if regime == "exact" else spectral_nll)(p - off, args)

    @jax.jit
    def cox_snell(p, a):
        w = a.weight.ravel()
        u = lambda q: jnp.log(spectral_model_psd(q, a)).ravel()
        J = jax.jacfwd(u)(p)            # (M,P)
        H = jax.jacfwd(jax.jacfwd(u))(p)  # (M,P,P)
        F = jnp.einsum("m,mi,mj->ij", w, J, J)
        A = 0.5 * (jnp.einsum("m,mij,mk->ijk", w, H, J) - jnp.einsum("m,mik,mj->ijk", w, H, J)
                   - jnp.einsum("m,mjk,mi->ijk", w, H, J) - jnp.einsum("m,mi,mj,mk->ijk", w, J, J, J))
        Fi = jnp.linalg.inv(F)
        return Fi @ jnp.einsum("ijk,jk->i", A, Fi), jnp.sqrt(jnp.diag(Fi))

    sampler = sb.CirculantSampler(sb.autocovariance(sb.K, sb.GAMMA, sb.W, sb.DT, sb.EPS2, nf))
    rng = np.random.default_rng(int(argv[3]) if len(argv) > 3 else 7)
    con, unc, cor, ses, bnd = [], [], [], [], []
    t0 = time.time()
    mdl = get_model("standard")
    for y in sampler.draw(rng, n):
        rec = bt.Recording(y, frame_interval=sb.DT, exposure=sb.W, temperature=sb.T)
        try:
            fit = bt.calibrate(rec, method="likelihood", likelihood=regime)
        except bt.FitError:
            continue
        v = np.array([fit.params[k] for k in sb.NAMES])
        layout = make_layout([rec], "shared", True)
        sargs = _spectral_args([rec], layout, mdl, 1, None)
        args = make_exact_args([rec], layout, mdl) if regime == "exact" else sargs
        off = jnp.array([0.0, 0.0, 4.0 * sb.EPS2])
        out = fit_ml(shifted, jnp.asarray(v) + off, (args, off))
        u = np.asarray(out.value - off) if bool(out.success) else np.full(3, np.nan)
        b, se = cox_snell(jnp.asarray(u), sargs)
        con.append(v)
        unc.append(u)
        cor.append(u - np.asarray(b))
        ses.append(np.asarray(se))
        bnd.append("tracking_var" in fit.at_bounds)
    tr = np.array([sb.K, sb.GAMMA, sb.EPS2])
    print(n, nf, regime, "time", time.time()-t0, "bound frac", np.mean(bnd), "neg", np.nanmean(np.array(unc)[:,2]<0))
    for nm, a in (("con", con), ("unc", unc), ("cs", cor)):
        a = np.array(a)
        rel = a / tr - 1
        z = (a - tr) / np.array(ses)
        sdse = np.std(a, 0) / np.sqrt(np.mean(np.array(ses) ** 2, 0))
        print(nm, "bias %", np.round(100 * np.nanmean(rel, 0), 2),
              "MC SE %", np.round(100 * np.nanstd(rel, 0) / np.sqrt(len(rel)), 2),
              "median %", np.round(100 * np.nanmedian(rel, 0), 2),
              "coverage", np.round(np.mean(np.abs(z) < 1.96, 0), 3), "SD/SE", np.round(sdse, 3))


# ------------------------------------------------------------------------------------------
# Session 12: parametric-bootstrap bias correction
# ------------------------------------------------------------------------------------------
def _boot_mean(tpl, v, key, n_boot, n_frames, max_iter):
    """Mean, median and mean log of the exact refits of ``n_boot`` recordings simulated
    from ``v`` by blurtrap's exact frame sampler; fraction of rows whose Newton step criterion
    was met."""
    from blurtrap.inference._bias import refit_exact, refit_start

    y = bt.simulate(v[0], v[1], sb.W, sb.DT, n_frames, key=key, temperature=sb.T,
                    n_traces=n_boot, method="exact_frames", tracking_std=float(np.sqrt(v[2])))
    val, ok = refit_exact(tpl, np.asarray(y).reshape(n_boot, n_frames), refit_start(v, sb.T),
                          max_iter)
    return val.mean(0), np.median(val, 0), np.log(val[:, :2]).mean(0), ok.mean()


def _valid(c, v):
    """The corrected value kept valid: eps^2 >= 0; k, gamma > 0 (else the ratio form)."""
    from blurtrap.inference._bias import _keep_valid

    return _keep_valid(c, v, ("positive", "positive", "nonnegative"))


def run_bootstrap(n, n_boot, seed, out, n_iv, max_iter, iterate):
    """Fit ``n`` circulant-embedding datasets (exact likelihood, 4096 frames) and their
    bootstrap corrections; checkpoint to ``out`` every 10 datasets."""
    from blurtrap.inference._bias import exact_template
    from blurtrap.inference._problems import rec_meta

    nf = 4096
    sampler = sb.CirculantSampler(sb.autocovariance(sb.K, sb.GAMMA, sb.W, sb.DT, sb.EPS2, nf))
    rng = np.random.default_rng(seed)
    rows = {k: [] for k in ("v", "m1", "med1", "lg1", "ok1", "m2", "ok2", "bound", "iv",
                            "t_fit", "t_boot")}
    tpl = None
    for i, y in enumerate(sampler.draw(rng, n)):
        rec = bt.Recording(y, frame_interval=sb.DT, exposure=sb.W, temperature=sb.T)
        t0 = time.time()
        try:
            fit = bt.calibrate(rec, method="likelihood", likelihood="exact")
        except bt.FitError:
            continue
        t1 = time.time()
        if tpl is None:
            tpl = exact_template(get_model("standard"), make_layout([rec], "shared", True),
                                 rec_meta([rec]), nf)
        v = np.array([fit.params[k] for k in sb.NAMES])
        key = jax.random.fold_in(jax.random.PRNGKey(seed), i)
        m1, med1, lg1, ok1 = _boot_mean(tpl, v, key, n_boot, nf, max_iter)
        m2, ok2 = np.full(3, np.nan), np.nan
        if iterate:  # second bootstrap at the once-corrected value: theta = fit - b(theta)
            m2, _, _, ok2 = _boot_mean(tpl, _valid(2 * v - m1, v), jax.random.fold_in(key, 1),
                                       n_boot, nf, max_iter)
            m2 = m2 - _valid(2 * v - m1, v)  # the bias at the corrected value
        t2 = time.time()
        iv = np.full((3, 2), np.nan)
        if i < n_iv:
            iv = np.array([fit.intervals[k] for k in sb.NAMES])
        for k, x in zip(rows, (v, m1, med1, lg1, ok1, m2, ok2, "tracking_var" in fit.at_bounds,
                                iv, t1 - t0, t2 - t1)):
            rows[k].append(x)
        if (i + 1) % 10 == 0 or i + 1 == n:
            np.savez(out, n_boot=n_boot, seed=seed, max_iter=max_iter,
                     **{k: np.array(x) for k, x in rows.items()})
            print(i + 1, "datasets", f"{time.time() - t0:.1f} s last", flush=True)


def _line(name, a, tr):
    rel = a / tr - 1
    se = np.nanstd(rel, 0) / np.sqrt(np.sum(np.isfinite(rel), 0))
    sd = np.nanstd(a, 0) / tr
    print(f"| {name} | " + " | ".join(f"{100 * b:+.2f} ({100 * s:.2f})" for b, s in
                                        zip(np.nanmean(rel, 0), se))
          + " | " + " | ".join(f"{100 * x:.1f}" for x in sd) + " |")


def report_bootstrap(path):
    d = np.load(path)
    v, m1 = d["v"], d["m1"]
    tr = np.array([sb.K, sb.GAMMA, sb.EPS2])
    print(f"{len(v)} datasets, B = {int(d['n_boot'])}, seed {int(d['seed'])}; eps^2 at bound "
          f"{100 * d['bound'].mean():.1f} %; refit step criterion met {100 * d['ok1'].mean():.1f} %;"
          f" median s/dataset: fit {np.median(d['t_fit']):.2f}, bootstrap "
          f"{np.median(d['t_boot']):.2f}")
    print("| estimate | bias % k | gamma | eps^2 | SD % k | gamma | eps^2 |")
    print("|---|---|---|---|---|---|---|")
    _line("MLE (eps^2 >= 0)", v, tr)
    c1 = np.array([_valid(2 * a - b, a) for a, b in zip(v, m1)])
    _line("bootstrap, additive (2 fit - mean)", c1, tr)
    r = v.copy()
    r[:, :2] = v[:, :2] ** 2 / m1[:, :2]
    r[:, 2] = c1[:, 2]
    _line("bootstrap, ratio (fit^2 / mean)", r, tr)
    lg = v.copy()
    lg[:, :2] = np.exp(2 * np.log(v[:, :2]) - d["lg1"])
    lg[:, 2] = c1[:, 2]
    _line("bootstrap, log scale", lg, tr)
    if np.isfinite(d["m2"]).any():
        c2 = np.array([_valid(a - b2, a) for a, b2 in zip(v, d["m2"])])
        _line("bootstrap iterated once (fit - bias at corrected)", c2, tr)
    bound = d["bound"].astype(bool)
    for name, sel in (("at the bound", bound), ("interior", ~bound)):
        print(f"eps^2 {name} (n = {int(sel.sum())}):")
        _line("MLE", v[sel], tr)
        _line("bootstrap, additive", c1[sel], tr)
    iv = d["iv"]
    have = np.isfinite(iv[:, 0, 0])
    if have.any():
        for name, c in (("additive", c1), ("ratio", r)):
            inside = (iv[have, :, 0] <= c[have]) & (c[have] <= iv[have, :, 1])
            print(f"{name}: corrected inside the profile interval (k, gamma, eps^2) %",
                  np.round(100 * inside.mean(0), 1), "of", int(have.sum()))
        cov = (iv[have, :, 0] <= tr) & (tr <= iv[have, :, 1])
        print("profile interval coverage %", np.round(100 * cov.mean(0), 1))


def main():
    argv = sys.argv[1:]
    if argv and argv[0] == "boot":
        ap = argparse.ArgumentParser(prog="study_boundary_bias.py boot")
        ap.add_argument("n", type=int)
        ap.add_argument("n_boot", type=int)
        ap.add_argument("out")
        ap.add_argument("--seed", type=int, default=7)
        ap.add_argument("--intervals", type=int, default=0)
        ap.add_argument("--max-iter", type=int, default=20)
        ap.add_argument("--iterate", action="store_true")
        a = ap.parse_args(argv[1:])
        run_bootstrap(a.n, a.n_boot, a.seed, a.out, a.intervals, a.max_iter, a.iterate)
    elif argv and argv[0] == "boot-report":
        report_bootstrap(argv[1])
    else:
        three_ways(argv)


if __name__ == "__main__":
    main()
