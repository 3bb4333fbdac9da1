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
"""
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
argv = sys.argv[1:]
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
