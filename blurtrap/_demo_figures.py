"""The figures of ``blurtrap demo``: the paper's Figs. 1 and 3-7 from the simulated experiment
and its fits, PSD residuals before and after the blur model, the naive-equipartition error map
and the posterior corner plot. A figure that fails is reported and the others are still made.
"""

from __future__ import annotations

from ._demo_experiment import naive_error_grid
from ._demo_fits import DemoRun
from ._demo_report import _k_by_power


class _Figures:
    """Saves figures into ``outdir`` and lists them in ``figures`` (file, caption)."""

    def __init__(self, outdir, figures: list, log):
        self.outdir = outdir
        self.figures = figures
        self.log = log
        self.errors = []

    def save(self, fig, name, caption):
        from .plotting import save as save_figure  # saves, then closes the pyplot figure

        path = self.outdir / f"{name}.png"
        save_figure(fig, path, dpi=110)
        self.figures.append({"file": path.name, "caption": caption})

    def attempt(self, name, make, caption):
        try:
            self.save(make(), name, caption)
        except Exception as exc:
            self.errors.append(f"{name}: {type(exc).__name__}: {exc}")
            self.log(f"figure {name}: FAILED ({exc})")


def _fig1(run: DemoRun, figs: _Figures, bp) -> None:
    cfg = run.cfg
    x1, k1, g1, dt1 = run.fig1
    figs.attempt("fig1a_universal_curve",
                 lambda: bp.fig1a_universal_curve(x1, cfg.fig1_windows, k1, g1,
                                                  temperature=cfg.temperature,
                                                  frame_interval=dt1),
                 "Fig. 1a: simulated fractional variance vs alpha = W/tau for the paper's "
                 "three settings, collapsing on S(alpha).")

    def f1b():
        from .data import Recording

        j = list(cfg.fig1_windows).index(4e-3) if 4e-3 in cfg.fig1_windows else -1
        rec = Recording(x1[2, j, 0], frame_interval=dt1, exposure=cfg.fig1_windows[j],
                        temperature=cfg.temperature)
        return bp.fig1b_histogram(rec, {"k": k1[2], "gamma": g1[2],
                                        "temperature": cfg.temperature})

    figs.attempt("fig1b_histogram", f1b,
                 "Fig. 1b: histogram of blurred frames (setting iii, W = 4 ms) with the "
                 "predicted blurred normal (solid) and the blur-free normal (dotted).")


def _fig4(run: DemoRun, figs: _Figures, bp) -> None:
    """Stiffness vs power: needs a blur-corrected k at every power (per-power fits, else the
    joint fit)."""
    cfg, powers, res, joint = run.cfg, run.powers, run.res, run.joint
    corr = {}
    for p in powers:
        r = res.get(f"vve_{p}")
        if r is not None:
            corr[p] = (r.k, r.k_err)
    if len(corr) < len(powers) and joint is not None:  # --quick: the joint fit
        kj, ej = _k_by_power(joint, list(run.recs), powers)
        corr = {p: (kk, ee) for p, kk, ee in zip(powers, kj, ej, strict=True)}
    if len(corr) == len(powers):
        pfits = {w: res[f"vvp_{w}"] for w in cfg.power_exposures if f"vvp_{w}" in res}
        figs.attempt("fig4_stiffness_vs_power",
                     lambda: bp.fig4_stiffness_vs_power(
                         list(run.recs), corr, naive_exposures=cfg.naive_exposures,
                         power_fits=pfits, truth_c=cfg.c),
                     "Fig. 4: naive equipartition k at W = 1 and 2 ms vs the blur-corrected "
                     "k (variance vs exposure); dashed: k = cP blur-model fits.")


def _psd_figs(run: DemoRun, figs: _Figures, bp) -> None:
    """Figs. 6 and 7 and the residuals before/after (lowest power, W = dt)."""
    psd_fits = run.psd_fits
    if "standard" in psd_fits:
        rec0 = run.at(run.powers[0], run.cfg.frame_interval)
        fits0 = [psd_fits[m][0] for m in ("standard", "naive", "naive_aliased")
                 if m in psd_fits]
        figs.attempt("fig6_psd", lambda: bp.fig6_psd(rec0, fits0),
                     "Fig. 6: blocked PSD (lowest power, W = dt) with the blur-corrected aliased "
                     "fit (solid), naive (dashed) and naive aliased (dotted).")
        figs.attempt("fig7_deviation", lambda: bp.fig7_deviation(rec0, psd_fits["standard"][0]),
                     "Fig. 7: data/model of the blur-corrected PSD fit with the 1/sqrt(n_b) "
                     "band; histogram with the normal and Gamma(n_b) laws.")
        if "naive" in psd_fits:
            figs.attempt("residuals_before_after",
                         lambda: bp.residuals_before_after(psd_fits["naive"][0],
                                                           psd_fits["standard"][0], rec0,
                                                           labels=("before (naive)",
                                                                   "after (standard)")),
                         "PSD residuals before (naive model) and after adding motion blur, "
                         "aliasing and tracking noise (standard model).")


def make_figures(run: DemoRun, outdir, figures: list, log) -> bool:
    """Make and save every figure whose inputs exist; ``figures`` collects (file, caption)
    of those written. Raises ``RuntimeError`` listing the figures that failed."""
    from . import plotting as bp

    cfg = run.cfg
    truth = {"k": cfg.ks[0], "gamma": cfg.gamma, "tracking_var": cfg.tracking_std**2,
             "temperature": cfg.temperature}
    figs = _Figures(outdir, figures, log)
    if run.fig1 is not None:
        _fig1(run, figs, bp)
    if run.joint is not None:
        figs.attempt("fig3_fractional_variance",
                     lambda: bp.fig3_fractional_variance(list(run.recs), run.joint),
                     "Fig. 3: (var - eps^2)/(kT/k) vs alpha at 4 powers, rescaled with the "
                     "joint variance-vs-exposure fit, on S(alpha).")
    if run.recs is not None:
        _fig4(run, figs, bp)
    if "recording" in run.drift_info:
        figs.attempt("fig5_highpass",
                     lambda: bp.fig5_highpass(run.drift_info["recording"], run.drift_info["fc"],
                                              params=truth),
                     "Fig. 5: variance vs high-pass cut-off of a drifting recording "
                     "(lowest power), linear fit extrapolated to 0 Hz.")
    _psd_figs(run, figs, bp)
    kg, wg, err = naive_error_grid(cfg)
    figs.attempt("naive_error_map",
                 lambda: bp.naive_error_map(kg, wg, err,
                                            title=f"naive equipartition error, R = "
                                                  f"{cfg.radius * 1e6:.3g} um, eps = "
                                                  f"{cfg.tracking_std * 1e9:.2g} nm"),
                 "Relative error of naive equipartition k over stiffness x exposure for this "
                 "bead (analytic, var = kT/k S(alpha) + eps^2).")
    if run.posterior_samples:
        keep = {k: v for k, v in run.posterior_samples.items()
                if k in ("k", "gamma", "tracking_var")} or run.posterior_samples
        figs.attempt("corner", lambda: bp.corner(keep, truths=truth),
                     "Posterior of the lowest-power recording (short emcee run).")
    if figs.errors:
        raise RuntimeError("; ".join(figs.errors))
    return True
