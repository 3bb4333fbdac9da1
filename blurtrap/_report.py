"""``blurtrap calibrate/diagnose MANIFEST --report DIR``: what a lab notebook needs of a
calibration of the user's own recordings, as ``DIR/report.md`` in lab units with PNG figures
(:mod:`._report_figures`) and the result as strict JSON (SI units).

DIR is created when missing; a DIR that is a file is refused before anything is fitted. Only
the files the report writes are replaced (``report.md``, ``result.json`` or
``diagnosis.json``, ``spectrum_*.png``, ``histogram_*.png``, ``ranking.png``,
``before_after.png``); nothing else in DIR is touched.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from . import _report_figures as rf

#: symbol and meaning of the rows of the parameter table (else the parameter's description)
_TABLE_NAMES = {"k": ("k", "stiffness"), "c": ("c = k/P", "stiffness per laser power"),
                "gamma": ("gamma", "friction"),
                "tracking_var": ("eps^2", "tracking-error variance"),
                "displacement_sensitivity": ("Rd", "displacement sensitivity"),
                "force_sensitivity": ("Rf = k Rd", "force sensitivity")}


def report_dir(path) -> Path:
    """The report folder, created when missing (parents too); a clear error when `path` is a
    file or cannot be created. Called before any fit, so a bad DIR costs nothing."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--report {path}: is a file, not a directory; give a folder for "
                         "report.md and its figures (it is created when missing)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--report {path}: cannot create the folder ({exc.strerror or exc})"
                         ) from None
    return out


def _recordings(source):
    """The recordings of a manifest / NPZ path as loaded (raw positions, before any line
    subtraction the fit may do)."""
    from .data import Recording, load

    data: Any = load(source)
    return [data] if isinstance(data, Recording) else list(data)


def _num(v, fmt: str) -> str:
    return f"{v:{fmt}}" if v is not None and math.isfinite(v) else "-"


def _interval(lo, hi, fac) -> str:
    if not (math.isfinite(lo) or math.isfinite(hi)):
        return "-"
    return f"[{_num(lo * fac, '.4g')}, {_num(hi * fac, '.4g')}]"


def _row(name, value, error, unit, interval="-", kind="") -> str:
    return (f"| {name} | {_num(value, '.6g')} | {_num(error, '.2g')} | {unit} | {interval}"
            f"{' ' + kind if kind else ''} |")


def parameter_table(fit) -> list[str]:
    """The fitted parameters in lab units (k, gamma, D, eps, f_c, effect parameters; Rd and
    Rf for volts), each with its standard error and 95 % interval."""
    from .effects import lab_units

    ivs, kinds = fit.intervals, fit.interval_kinds
    lines = ["| parameter | value | +- SE | unit | 95 % interval |", "|---|---|---|---|---|"]
    for name in fit.param_names:
        p = fit[name]
        base = name.split("[")[0]
        fac = lab_units(base)[0]
        lo, hi = ivs.get(name, (math.nan, math.nan))
        sym, what = _TABLE_NAMES.get(base, (base, p.description))
        label = f"{sym}{name[len(base):]} ({what})"
        lines.append(_row(label, p.lab_value, p.lab_error, p.lab_unit,
                          _interval(lo, hi, fac), kinds.get(name, "")))
        if name == "tracking_var":
            lines.append(_eps_row(fit, lo, hi))
    if math.isfinite(fit.gamma):
        d = fit["D"]
        g_lo, g_hi = ivs.get("gamma", (math.nan, math.nan))
        kt = d.value * fit.gamma
        d_iv = _interval(kt / g_hi if g_hi > 0 else math.nan,
                         kt / g_lo if g_lo > 0 else math.inf, 1e12)
        lines.append(_row("D = kT/gamma (diffusion)", d.lab_value, d.lab_error, d.lab_unit,
                          d_iv))
        if "c" not in fit.param_names:
            first = " (recording 0)" if _k_varies(fit) else ""
            lines.append(_row(f"f_c = k/(2 pi gamma) (corner frequency){first}",
                              fit.corner_frequency, fit.corner_frequency_err, "Hz"))
    return lines


def _eps_row(fit, lo, hi) -> str:
    tv, tv_err = max(fit.tracking_var, 0.0), fit.tracking_var_err
    eps = math.sqrt(tv)
    err = tv_err / (2 * eps) if eps > 0 else math.nan
    iv = _interval(math.sqrt(max(lo, 0.0)) if math.isfinite(lo) else math.nan,
                   math.sqrt(hi) if math.isfinite(hi) and hi >= 0 else math.nan, 1e9)
    return _row("eps (tracking error rms)", eps * 1e9, err * 1e9, "nm", iv)


def _k_varies(fit) -> bool:
    return len({float(k) for k in fit.k_per_recording}) > 1


def per_recording_table(fit, recs) -> list[str]:
    """k and f_c of each recording when the stiffness differs between recordings."""
    if not _k_varies(fit):
        return []
    lines = ["| recording | k [pN/nm] | +- SE [pN/nm] | f_c [Hz] |", "|---|---|---|---|"]
    for i, (k, e) in enumerate(zip(fit.k_per_recording, fit.k_per_recording_err,
                                   strict=False)):
        name = rf.label(recs[i], i) if i < len(recs) else f"recording {i}"
        fc = float(k) / (2 * math.pi * fit.gamma) if math.isfinite(fit.gamma) else math.nan
        lines.append(f"| {name} | {_num(float(k) * 1e3, '.6g')} | "
                     f"{_num(float(e) * 1e3, '.2g')} | {_num(fc, '.5g')} |")
    return lines


def recordings_table(recs) -> list[str]:
    lines = ["| recording | frames | dt [ms] | W [ms] | T [K] | P [mW] | positions |",
             "|---|---|---|---|---|---|---|"]
    for i, r in enumerate(recs):
        p = "-" if r.laser_power is None else f"{r.laser_power * 1e3:.4g}"
        meta = getattr(r, "metadata", None) or {}
        read = str(meta.get("position_unit", "m")) if hasattr(meta, "get") else "m"
        unit = "V" if r.position_unit == "V" else ("m" if read in ("m", "V") else f"m (read from {read})")
        lines.append(f"| {rf.label(r, i)} | {r.n_frames} | {r.frame_interval * 1e3:.6g} | "
                     f"{float(r.exposure) * 1e3:.6g} | {float(r.temperature):g} | {p} | {unit} |")
    return lines


def fit_section(fit, recs) -> list[str]:
    """The parameter table, per-recording k, goodness of fit and notes of one fit."""
    lines = [f"Method `{fit.method}`, model `{fit.model}`, {fit.n_recordings} recording(s), "
             f"{fit.n_frames} frames, T = {fit.temperature:g} K"
             + ("" if fit.converged else " (**the fit did not converge**)") + ".", ""]
    lines += parameter_table(fit) + [""]
    per = per_recording_table(fit, recs)
    if per:
        lines += per + [""]
    g = fit.gof or {}
    if "statistic" in g:
        lines += [f"Goodness of fit ({g.get('test', 'gof')}): statistic = "
                  f"{_num(g['statistic'], '.4g')}, dof = {g.get('dof')}, "
                  f"p = {_num(g.get('p_value', math.nan), '.3g')}.", ""]
    notes = [f"{b} is at its lower bound (0)" for b in fit.at_bounds] + list(fit.notes)
    if notes:
        lines += ["Notes:", ""] + [f"- {n}" for n in notes] + [""]
    return lines


def _figure_lines(figs: rf.Figures) -> list[str]:
    lines = ["## Figures", ""]
    for file, caption in figs.entries:
        lines += [f"![{file}]({file})", "", f"*{caption}*", ""]
    if figs.skipped:
        lines += ["Not drawn:", ""] + [f"- {s}" for s in figs.skipped] + [""]
    if figs.failed:
        lines += ["**Figures that failed:**", ""] + [f"- {s}" for s in figs.failed] + [""]
    return lines


def _header(title: str, source, recs) -> list[str]:
    from . import __version__

    return [f"# {title}", "", f"Data: `{source}`; blurtrap {__version__}. Lab units "
            "throughout (SI in the JSON file).", "", "## Recordings", ""] + (
        recordings_table(recs) + [""])


def _finish(out: Path, lines, figs, json_name: str, payload) -> dict:
    from .cli import dumps_json

    (out / json_name).write_text(dumps_json(payload) + "\n")
    (out / "report.md").write_text("\n".join(lines))
    return {"dir": str(out), "report": str(out / "report.md"),
            "files": ["report.md", json_name] + figs.files, "failed": list(figs.failed)}


def write_calibration_report(out: Path, fit, source, posterior=None) -> dict:
    """``report.md``, ``result.json`` and the figures of one calibration into `out`; with
    `posterior` (``calibrate --posterior``) its summary and its samples' statistics too.

    **Returns:** ``{"dir", "report", "files", "failed"}`` (the files written, relative to
    `out`, and the figures that failed)."""
    recs = _recordings(source)
    figs = rf.Figures(out)
    rf.recording_figures(figs, recs, fit)
    lines = _header("blurtrap calibration report", source, recs)
    lines += ["## Result", ""] + fit_section(fit, recs)
    payload = fit.to_dict()
    if posterior is not None:
        lines += ["## Posterior (emcee)", "", "```", posterior.summary(), "```", ""]
        payload["posterior"] = posterior.to_dict()
    lines += _figure_lines(figs)
    return _finish(out, lines, figs, "result.json", payload)


def _ranking_table(d) -> list[str]:
    lines = ["| rank | effect | dlogL | dAIC | p | verdict | evidence |",
             "|---|---|---|---|---|---|---|"]
    for i, c in enumerate(d.ranking, 1):
        verdict = ("significant" if c.significant else "not significant") + (
            "" if c.plausible else ", IMPLAUSIBLE") + (
            ", required by the declared detector" if c.required else "")
        ev = str(c.evidence).replace("|", "/")
        lines.append(f"| {i} | `{c.effect}` | {_num(c.delta_loglik, '.2f')} | "
                     f"{_num(c.delta_aic, '.2f')} | {_num(c.p_value, '.3g')} | {verdict} | "
                     f"{ev} |")
    return lines


def _verdict(d) -> list[str]:
    g = d.gof
    head = (f"Model `{d.model}`: **{'adequate' if d.adequate else 'NOT adequate'}** "
            f"(goodness of fit p = {_num(g.get('p_value', math.nan), '.3g')}; a candidate is "
            f"significant at p < {d.threshold:.3g}, Bonferroni).")
    top = d.ranking[0] if d.ranking else None
    if top is None:
        return [head, "", "No candidate effect applies to these data."]
    best = d.best
    what = (f"Missing effect: **`{best.effect}`** (ranked first)." if best is not None else
            f"Top candidate: `{top.effect}` (not significant).")
    return [head, "", what]


def _before_after(d, recs, figs: rf.Figures) -> list[str]:
    """The before/after figure and the refit's table when the best candidate was refitted."""
    top = d.ranking[0] if d.ranking else None
    if top is None or not (top.significant or top.required):
        figs.skipped.append("before_after.png: no candidate is significant, so nothing was "
                            "added and refitted")
        return []
    if top.fit is None:
        figs.skipped.append(f"before_after.png: {top.effect} is tested outside the likelihood "
                            "(no refit with it added)")
        return []
    after = top.fit
    try:  # volts: the base fit's Rd for both rows
        view = [rf.in_metres(r, d.fit) for r in recs]
    except ValueError as exc:
        figs.skipped.append(f"before_after.png: {exc}")
    else:
        figs.attempt("before_after",
                     lambda: rf.before_after_figure(d.fit, after, view, top.effect),
                     f"PSD residuals (data/model, log-binned mean with its expected +-2 sd "
                     f"band) of the model {d.model} (before) and with {top.effect} added "
                     "(after).")
    return ([f"## Refit with `{top.effect}` added", ""] + change_table(d.fit, after) + [""]
            + fit_section(after, recs))


def change_table(before, after) -> list[str]:
    """The parameters both fits share, before and after adding the effect (lab units), and
    the change in standard errors of the refit."""
    lines = [f"| parameter | {before.model} | {after.model} | unit | change [SE] |",
             "|---|---|---|---|---|"]
    for name in [n for n in before.param_names if n in after.param_names]:
        b, a = before[name], after[name]
        z = (a.lab_value - b.lab_value) / a.lab_error if a.lab_error > 0 else math.nan
        lines.append(f"| {name} | {_num(b.lab_value, '.6g')} | {_num(a.lab_value, '.6g')} | "
                     f"{a.lab_unit} | {_num(z, '+.2f')} |")
    g = [f.gof.get("p_value", math.nan) for f in (before, after)]
    lines.append(f"| goodness of fit p | {_num(g[0], '.3g')} | {_num(g[1], '.3g')} | | |")
    return lines


def write_diagnosis_report(out: Path, diagnosis, source) -> dict:
    """``report.md``, ``diagnosis.json`` and the figures of one diagnosis into `out`: the
    verdict, the ranking with its evidence, the base fit, the refit with the best candidate
    added and the residuals before/after.

    **Returns:** as :func:`write_calibration_report`."""
    d = diagnosis
    recs = _recordings(source)
    figs = rf.Figures(out)
    figs.attempt("ranking", lambda: rf.ranking_figure(d),
                 "Candidate missing effects ranked by AIC improvement (red: significant by "
                 "diagnose's verdict), with the adequacy verdict in the title.")
    refit = _before_after(d, recs, figs)
    rf.recording_figures(figs, recs, d.fit)
    lines = _header("blurtrap diagnosis report", source, recs)
    lines += ["## Verdict", ""] + _verdict(d) + [""]
    if d.ranking:
        lines += ["## Ranking of candidate effects", ""] + _ranking_table(d) + [""]
    if d.notes:
        lines += ["Notes:", ""] + [f"- {n}" for n in d.notes] + [""]
    lines += refit
    lines += [f"## Fit of the model `{d.model}`", ""] + fit_section(d.fit, recs)
    lines += _figure_lines(figs)
    return _finish(out, lines, figs, "diagnosis.json", d.to_dict())
