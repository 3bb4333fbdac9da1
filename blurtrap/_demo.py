"""``blurtrap demo``: simulate the experiment of Wong & Halvorsen (2006) and calibrate it every
way the package knows, then write figures, a Markdown report and a table against the truth.

The experiment and its settings are in :mod:`._demo_experiment`, the calibration steps in
:mod:`._demo_fits`, the tables and ``report.md`` in :mod:`._demo_report` and the figures in
:mod:`._demo_figures`; this module runs the steps in order (a failed step is recorded and the
steps that need it are skipped) and writes the outputs.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from pathlib import Path
from typing import Any

from . import _demo_fits as fits
from ._demo_experiment import DemoConfig, quick_config, simulate_experiment, simulate_fig1
from ._demo_figures import make_figures
from ._demo_fits import DemoRun
from ._demo_report import _report, format_table


# ------------------------------------------------------------------------------------------
# progress log and steps
# ------------------------------------------------------------------------------------------
class _Log:
    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        if not self.quiet:
            print(f"[{time.perf_counter() - self.t0:6.1f} s] {msg}", file=sys.stderr, flush=True)


class _Steps:
    def __init__(self, log):
        self.log = log
        self.records = []

    def run(self, name, fn, *, needs=()) -> Any:  # the step's value; None if it failed
        missing = [n for n in needs if n is None]
        if missing:
            self.records.append({"step": name, "status": "skipped",
                                 "reason": "an earlier step it needs failed", "seconds": 0.0})
            self.log(f"{name}: skipped (an earlier step it needs failed)")
            return None
        self.log(f"{name} ...")
        t = time.perf_counter()
        try:
            out = fn()
        except Exception as exc:  # record, go on with the other steps
            dt = time.perf_counter() - t
            msg = f"{type(exc).__name__}: {exc}".strip().splitlines()[0]
            self.records.append({"step": name, "status": "failed", "error": msg,
                                 "seconds": dt, "traceback": traceback.format_exc()})
            self.log(f"{name}: FAILED ({msg})")
            return None
        dt = time.perf_counter() - t
        self.records.append({"step": name, "status": "ok", "seconds": dt})
        self.log(f"{name}: done ({dt:.1f} s)")
        return out

    def skip(self, name, reason):
        self.records.append({"step": name, "status": "skipped", "reason": reason,
                             "seconds": 0.0})
        self.log(f"{name}: skipped ({reason})")

    @property
    def failed(self):
        return [r for r in self.records if r["status"] == "failed"]


# ------------------------------------------------------------------------------------------
# the demo
# ------------------------------------------------------------------------------------------
def _log_start(log, cfg: DemoConfig, quick: bool) -> None:
    ws = list(cfg.exposures)
    log(f"blurtrap demo: bead radius {cfg.radius * 1e6:.3g} um, gamma = "
        f"{cfg.gamma * 1e6:.4g} pN s/um, k = {', '.join(f'{k * 1e3:.3g}' for k in cfg.ks)} "
        f"pN/nm, {len(ws)} exposures x {cfg.n_frames} frames at {cfg.fps:g} fps"
        + (" (quick)" if quick else ""))


def _run_calibrations(run: DemoRun, steps: _Steps, inference, log):
    """Every estimator in turn (after the simulation); returns the posterior note."""
    cfg, recs = run.cfg, run.recs
    steps.run("naive equipartition", lambda: fits.naive_equipartition(run), needs=(recs,))
    if cfg.per_power_variance:
        steps.run("variance vs exposure (each power)",
                  lambda: fits.variance_vs_exposure_each(run), needs=(recs,))
    else:
        steps.skip("variance vs exposure (each power)", "--quick")
    run.joint = steps.run("variance vs exposure (joint: k per power, shared gamma, eps^2)",
                          lambda: fits.variance_vs_exposure_joint(run), needs=(recs,))
    steps.run("variance vs power (k = c P)", lambda: fits.variance_vs_power(run), needs=(recs,))
    for model in cfg.psd_models:
        steps.run(f"blocked PSD fit, model {model}",
                  lambda model=model: fits.blocked_psd(run, model), needs=(recs,))
    if cfg.exact_likelihood:
        steps.run("exact likelihood", lambda: fits.exact_likelihood(run), needs=(recs,))
    else:
        steps.skip("exact likelihood", "--quick")
    posterior_note = None
    if not hasattr(inference, "sample_posterior"):
        posterior_note = "posterior: not available in this version"
        log(posterior_note)
        steps.skip("posterior", "not available in this version")
    elif not cfg.posterior:
        posterior_note = "posterior: skipped (--quick)"
        steps.skip("posterior", "--quick")
    else:
        run.posterior_samples = steps.run("posterior (short run)", lambda: fits.posterior(run),
                                          needs=(recs,))
    steps.run("drift: high-pass extrapolation (appendix B)", lambda: fits.drift(run),
              needs=(recs,))
    return posterior_note


def _settings(cfg: DemoConfig, quick: bool) -> dict:
    return {
        "bead_radius_um": cfg.radius * 1e6,
        "viscosity_mPa_s": cfg.viscosity * 1e3,
        "temperature_K": cfg.temperature,
        "gamma_true_pN_s_per_um": cfg.gamma * 1e6,
        "laser_power_mW": [p * 1e3 for p in cfg.powers],
        "k_true_pN_per_nm": [k * 1e3 for k in cfg.ks],
        "c_true_pN_per_nm_per_W": cfg.c * 1e3,
        "exposures_ms": [w * 1e3 for w in cfg.exposures],
        "frame_intervals_ms": [d * 1e3 for d in cfg.frame_intervals()],
        "camera_fps": cfg.fps,
        "tracking_nm": cfg.tracking_std * 1e9,
        "n_frames": cfg.n_frames,
        "seed": cfg.seed,
        "quick": bool(quick),
    }


def _write_outputs(summary: dict, run: DemoRun, outdir: Path, figures, steps: _Steps,
                   posterior_note) -> None:
    """``report.md`` and ``results.json``; a disk error marks the summary failed."""
    try:
        (outdir / "report.md").write_text(
            _report(summary, run.rows, run.cfg, figures, steps.records, run.drift_info,
                    posterior_note),
            encoding="utf-8")
        (outdir / "results.json").write_text(json.dumps(summary, indent=1), encoding="utf-8")
    except Exception as exc:  # pragma: no cover - disk errors
        summary["ok"] = False
        summary["steps"].append({"step": "report", "status": "failed", "error": str(exc)})


def demo(out="blurtrap-demo", *, quick=False, quiet=False, seed=0, config=None):
    """Run the demo; returns the JSON-able summary dict (see ``blurtrap demo --json``).

    Writes ``report.md``, ``results.json`` and PNG figures into `out`."""
    from . import inference

    cfg = config or (quick_config(seed) if quick else DemoConfig(seed=seed))
    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    log = _Log(quiet)
    steps = _Steps(log)
    t_start = time.perf_counter()
    _log_start(log, cfg, quick)
    run = DemoRun(cfg)
    run.recs = steps.run(
        f"simulate exposure series ({len(cfg.powers)} powers x {len(cfg.exposures)} exposures x "
        f"{cfg.n_frames} frames)", lambda: simulate_experiment(cfg))
    run.fig1 = steps.run("simulate Fig. 1 runs (3 settings, ExposureWindows)",
                         lambda: simulate_fig1(cfg))
    posterior_note = _run_calibrations(run, steps, inference, log)
    figures = []
    steps.run("figures", lambda: make_figures(run, outdir, figures, log))

    summary = {
        "ok": not steps.failed,
        "out": str(outdir),
        "settings": _settings(cfg, quick),
        "results": run.rows,
        "drift": {k: v for k, v in run.drift_info.items() if k != "recording"},
        "posterior": posterior_note or ("ok" if run.posterior_samples else "no samples"),
        "steps": [{k: v for k, v in s.items() if k != "traceback"} for s in steps.records],
        "figures": [f["file"] for f in figures],
        "report": str(outdir / "report.md"),
        "runtime_s": time.perf_counter() - t_start,
        "units": "lab (pN/nm, pN s/um, nm^2, ms, mW, Hz)",
    }
    _write_outputs(summary, run, outdir, figures, steps, posterior_note)
    summary["table"] = format_table(run.rows, cfg)
    return summary


def run_demo(args) -> int:
    """Entry point of ``blurtrap demo`` (argparse namespace with out, json, quick, seed)."""
    summary = demo(args.out, quick=bool(getattr(args, "quick", False)),
                   quiet=bool(getattr(args, "json", False)), seed=int(getattr(args, "seed", 0)))
    if getattr(args, "json", False):
        out = {k: v for k, v in summary.items() if k != "table"}
        print(json.dumps(out))
    else:
        print(summary["table"])
        if summary["posterior"] == "posterior: not available in this version":
            print(summary["posterior"])
        print(f"report: {summary['report']}  ({len(summary['figures'])} figures, "
              f"{summary['runtime_s']:.1f} s)")
    failed = [s for s in summary["steps"] if s["status"] == "failed"]
    if failed:
        names = ", ".join(s["step"] for s in failed)
        print(f"blurtrap demo: error: {len(failed)} step(s) failed: {names} "
              f"(see {summary['report']})", file=sys.stderr)
        return 1
    return 0
