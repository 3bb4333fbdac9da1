"""The tables and the report of ``blurtrap demo``: fits turned into rows in lab units with
the truth and % errors, the console and Markdown tables, and ``report.md``."""

from __future__ import annotations

import math

import numpy as np

from ._demo_experiment import DemoConfig


def _close(a, b) -> bool:
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b))


def _pct(est, true):
    if est is None or true is None or not np.isfinite(est) or not np.isfinite(true):
        return None
    return 100.0 * (est - true) / true


def _f(x):
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _k_by_power(result, recs, powers):
    ks = np.asarray(result.k_per_recording, dtype=float)
    es = np.asarray(result.k_per_recording_err, dtype=float)
    if ks.size == 1 and len(recs) > 1:
        ks, es = np.full(len(recs), ks[0]), np.full(len(recs), es[0])
    out_k, out_e = [], []
    for p in powers:
        sel = [i for i, r in enumerate(recs) if r.laser_power is not None
               and _close(r.laser_power, p)]
        if sel:
            out_k.append(float(np.mean(ks[sel])))
            out_e.append(float(np.mean(es[sel])))
        else:
            out_k.append(None)
            out_e.append(None)
    return out_k, out_e


def make_row(label, method, model, cfg, powers, ks, kerrs, gamma=None, gamma_err=None,
             tracking_var=None, exposure=None, note=None):
    """One table row in lab units, with the truth and the % errors."""
    truth_k = {float(p): float(cfg.c * p) for p in cfg.powers}
    row = {
        "label": label,
        "method": method,
        "model": model,
        "exposure_ms": None if exposure is None else float(exposure) * 1e3,
        "power_mW": [float(p) * 1e3 for p in powers],
        "k_pN_per_nm": [None if k is None else k * 1e3 for k in ks],
        "k_err_pN_per_nm": [None if e is None else _f(e * 1e3) for e in kerrs],
        "k_true_pN_per_nm": [truth_k[float(p)] * 1e3 for p in powers],
        "k_error_pct": [_pct(k, truth_k[float(p)]) for k, p in zip(ks, powers, strict=True)],
    }
    g_true = cfg.gamma
    if gamma is None:
        row.update(gamma_pN_s_per_um=None, gamma_err_pN_s_per_um=None, gamma_error_pct=None)
    elif np.ndim(gamma):
        row["gamma_pN_s_per_um"] = [_f(g * 1e6) for g in gamma]
        row["gamma_err_pN_s_per_um"] = [_f(e * 1e6) for e in gamma_err]  # pyright: ignore
        row["gamma_error_pct"] = [_pct(g, g_true) for g in gamma]
    else:
        row["gamma_pN_s_per_um"] = _f(gamma * 1e6)
        row["gamma_err_pN_s_per_um"] = _f(gamma_err * 1e6) if gamma_err is not None else None
        row["gamma_error_pct"] = _pct(gamma, g_true)
    row["gamma_true_pN_s_per_um"] = g_true * 1e6
    if tracking_var is not None:
        tv = np.atleast_1d(np.asarray(tracking_var, dtype=float)) * 1e18
        row["tracking_var_nm2"] = [float(v) for v in tv] if tv.size > 1 else float(tv[0])
    if note:
        row["note"] = note
    return row


def _fmt_k(k, pct):
    if k is None:
        return "-"
    return f"{k:.4f} ({pct:+.1f}%)" if pct is not None else f"{k:.4f}"


def _gamma_cell(row):
    g = row["gamma_pN_s_per_um"]
    if g is None:
        return "-"
    if isinstance(g, list):
        vals = [v for v in g if v is not None]
        if not vals:
            return "-"
        m = float(np.mean(vals))
        pct = _pct(m, row["gamma_true_pN_s_per_um"])
        return f"{m:.4f} ({pct:+.1f}%) *"
    return f"{g:.4f} ({row['gamma_error_pct']:+.1f}%)"


def format_table(rows, cfg: DemoConfig) -> str:
    """The console table: k per power [pN/nm] and gamma [pN s/um], with % error vs truth."""
    powers = [p * 1e3 for p in cfg.powers]
    head = ["method"] + [f"k @ {p:.0f} mW [pN/nm]" for p in powers] + ["gamma [pN s/um]"]
    truth = ["truth"] + [f"{k * 1e3:.4f}" for k in cfg.ks] + [f"{cfg.gamma * 1e6:.4f}"]
    body = [head, truth]
    for r in rows:
        cells = [r["label"]]
        pairs = zip(r["k_pN_per_nm"], r["k_error_pct"], strict=True)
        by_p = dict(zip(r["power_mW"], pairs, strict=True))
        for p in powers:
            k, pct = by_p.get(p, (None, None))
            cells.append(_fmt_k(k, pct))
        cells.append(_gamma_cell(r))
        body.append(cells)
    widths = [max(len(row[i]) for row in body) for i in range(len(head))]
    lines = []
    for n, row in enumerate(body):
        lines.append("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                               for i, (c, w) in enumerate(zip(row, widths, strict=True))))
        if n == 0:
            lines.append("  ".join("-" * w for w in widths))
    lines.append("(% = error vs truth; * = mean of per-power fits)")
    return "\n".join(lines)


def markdown_table(rows, cfg: DemoConfig) -> str:
    powers = [p * 1e3 for p in cfg.powers]
    head = (["method"] + [f"k @ {p:.0f} mW [pN/nm]" for p in powers]
            + ["gamma [pN s/um]", "eps^2 [nm^2]"])
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out.append("| **truth** | " + " | ".join(f"{k * 1e3:.4f}" for k in cfg.ks)
               + f" | {cfg.gamma * 1e6:.4f} | {cfg.tracking_std**2 * 1e18:.3g} |")
    for r in rows:
        pairs = zip(r["k_pN_per_nm"], r["k_error_pct"], strict=True)
        by_p = dict(zip(r["power_mW"], pairs, strict=True))
        cells = [r["label"]]
        for p in powers:
            k, pct = by_p.get(p, (None, None))
            cells.append(_fmt_k(k, pct))
        cells.append(_gamma_cell(r))
        tv = r.get("tracking_var_nm2")
        if tv is None:
            cells.append("-")
        elif isinstance(tv, list):
            cells.append(f"{np.mean(tv):.3g} *")
        else:
            cells.append(f"{tv:.3g}")
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def _report(summary, rows, cfg, figures, step_records, drift_info, posterior_note) -> str:
    from . import __version__

    s = summary["settings"]
    lines = [
        "# blurtrap demo: calibrating a blurred, aliased optical trap",
        "",
        f"blurtrap {__version__}. Simulated experiment after Wong & Halvorsen, Opt. Express 14, "
        "12517 (2006), section 4; all numbers in lab units.",
        "",
        "## Setup",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| bead radius | {s['bead_radius_um']:.3g} um (polystyrene, 3.063 um diameter) |",
        f"| viscosity, temperature | {s['viscosity_mPa_s']:.3g} mPa s, {s['temperature_K']:g} K |",
        f"| friction gamma = 6 pi eta r (truth) | {s['gamma_true_pN_s_per_um']:.4f} pN s/um |",
        f"| laser powers | {', '.join(f'{p:g}' for p in s['laser_power_mW'])} mW |",
        f"| stiffness k = c P (truth) | "
        f"{', '.join(f'{k:.3g}' for k in s['k_true_pN_per_nm'])} pN/nm "
        f"(c = {s['c_true_pN_per_nm_per_W']:.3g} pN/nm/W) |",
        f"| exposures W | {', '.join(f'{w:.3g}' for w in s['exposures_ms'])} ms |",
        f"| frame intervals | {', '.join(f'{d:.3g}' for d in s['frame_intervals_ms'])} ms "
        f"(camera {s['camera_fps']:g} fps; longer exposures at frame interval = W) |",
        f"| tracking error | {s['tracking_nm']:g} nm rms |",
        f"| frames per recording | {s['n_frames']} (simulate, method exact_frames) |",
        "",
        "## Results",
        "",
        "Stiffness per laser power and friction, estimate (error vs truth). `*`: mean of "
        "per-power fits. PSD and likelihood fits use the recordings at W = dt = "
        f"{cfg.frame_interval * 1e3:.3g} ms.",
        "",
        markdown_table(rows, cfg),
        "",
        "Naive equipartition ignores motion blur: blur lowers the measured variance by "
        "S(alpha), so kT/var over-estimates k, the more so the longer the exposure and the "
        "stiffer the trap. The blur-corrected methods agree with the truth to within a few "
        "standard errors (all standard errors are in `results.json`). The naive PSD fits "
        "look acceptable but return biased k and gamma (paper appendix C).",
        "",
    ]
    if drift_info:
        lines += [
            "### Drift (appendix B)",
            "",
            f"Lowest power with added slow drift: unfiltered variance "
            f"{drift_info['unfiltered_nm2']:.4g} nm^2, extrapolated drift-free variance "
            f"{drift_info['v0_nm2']:.4g} nm^2, model (no drift) "
            f"{drift_info['expected_nm2']:.4g} nm^2.",
            "",
        ]
    if posterior_note:
        lines += [posterior_note, ""]
    lines += ["## Figures", ""]
    for f in figures:
        lines += [f"![{f['file']}]({f['file']})", "", f"*{f['caption']}*", ""]
    lines += ["## Steps", "", "| step | status | time [s] |", "|---|---|---|"]
    for r in step_records:
        st = r["status"] + (f": {r['error']}" if r.get("error") else "") + (
            f" ({r['reason']})" if r.get("reason") else "")
        lines.append(f"| {r['step']} | {st} | {r['seconds']:.1f} |")
    lines += ["", f"Total runtime: {summary['runtime_s']:.1f} s.", "",
              "Reproduce with `blurtrap demo" + (" --quick" if s["quick"] else "")
              + f" --seed {s['seed']}`.", ""]
    return "\n".join(lines)
