"""The bodies of ``blurtrap calibrate``, ``diagnose``, ``simulate`` and ``design`` (their
parsers are in :mod:`blurtrap._cli_parser`): load, fit or diagnose, print the lab-unit table
or one JSON object, and write the ``--report DIR`` (:mod:`blurtrap._report`)."""

from __future__ import annotations

import math
import sys
from typing import Any

from ._cli_checks import (
    band_flag_words,
    check_bands,
    check_design,
    check_simulate,
    check_simulated_spread,
    not_identified_message,
)
from .cli import CliError, dumps_json


def _check_input_path(path) -> None:
    """A clear message for paths the loaders cannot take on the command line."""
    if not path.exists():
        raise CliError(f"{path}: no such file")
    if path.is_dir():
        raise CliError(f"{path} is a directory; give its manifest JSON (e.g. {path}/manifest.json)")
    if path.suffix.lower() in (".csv", ".txt", ".tsv"):
        raise CliError(
            f"{path}: a bare CSV does not say its frame interval, exposure or position unit; "
            "write a manifest JSON that lists it with those (see README, Data format), or load "
            "it in Python with blurtrap.load_csv(path, frame_interval=..., exposure=..., "
            "position_unit=...)")


def calibrate_command(args) -> int:
    """``blurtrap calibrate``: fit, print the table (or JSON), write the report."""
    from pathlib import Path

    from .data import holds_xy
    from .inference import FitError, calibrate

    path = Path(args.manifest)
    _check_input_path(path)
    check_bands(args)
    xy = holds_xy(path)
    if xy:
        _refuse_for_xy(args)
    report = _report_dir(args)
    kw = dict(method=args.method, model=args.model, likelihood=args.likelihood)
    if args.k_mode is not None:
        kw["k"] = args.k_mode
    if args.n_blocks is not None:
        kw["n_blocks"] = args.n_blocks
    if args.f_range is not None:
        kw["f_range"] = tuple(args.f_range)
    if args.friction is not None:
        kw["friction"] = args.friction
    if args.exclude:
        kw["excluded_ranges"] = [tuple(r) for r in args.exclude]
    kw["lines"] = args.lines
    if args.fix:
        kw["fixed"] = _fixed_arg(args.fix)
    if args.diffusion is not None:  # calibrate checks that the method uses it
        if not (1e-7 <= args.diffusion <= 1e4):
            raise CliError(f"--diffusion is in um^2/s (a 1 um bead in water: ~0.2 um^2/s) and "
                           f"must be plausible, 1e-7..1e4 um^2/s; got {args.diffusion:g}"
                           + (" (this looks like m^2/s: 1e-13 m^2/s = 0.1 um^2/s)"
                              if 0 < args.diffusion < 1e-7 else ""))
        kw["diffusion"] = args.diffusion * 1e-12
    if xy:
        return _calibrate_xy(path, kw, args.json)
    try:
        result = calibrate(str(path), **kw)
    except (ValueError, FitError) as err:  # the band options by their flags
        if args.f_range is None and not args.exclude:
            raise
        raise type(err)(band_flag_words(str(err))) from err
    post = None
    if args.posterior:
        from .inference import sample_posterior

        if not args.json:
            print("sampling the posterior (emcee)...", file=sys.stderr)
        steps = args.steps if args.steps is not None else "auto"
        post = sample_posterior(str(path), model=args.model, n_steps=steps,
                                n_walkers=args.walkers, k=kw.get("k"),
                                progress=not args.json and sys.stderr.isatty())
    if report is not None:
        from ._report import write_calibration_report as write

        report = write(report, result, str(path), posterior=post)
    if args.json:
        out = result.to_dict() | ({"report": report} if report else {})
        if post is not None:
            out["posterior"] = post.to_dict()
        print(dumps_json(out))
    else:
        print(result.summary())
        if post is not None:
            print(post.summary())
    return _report_done(report, args.json)


def _refuse_for_xy(args) -> None:
    """The calibrate options an x/y manifest cannot take, refused before any fit."""
    for flag, given in (("--report", args.report is not None), ("--posterior", args.posterior)):
        if given:
            raise CliError(f"{args.manifest}: {flag} is not available for x/y recordings yet; "
                           "run without it, or use Python (bt.calibrate_xy(xy); its .joint is "
                           "the CalibrationResult of the two principal axes)")
    if args.k_mode is not None:
        raise CliError(f"{args.manifest}: --k-mode cannot be used with x/y recordings: k is "
                       "fitted once per principal axis, with one shared gamma")


def _calibrate_xy(path, kw: dict, as_json: bool) -> int:
    """x/y recordings: principal axes, k per axis, one shared gamma (``calibrate_xy``) for
    each entry; the summaries, or one JSON object (``{"xy": [...]}`` for several)."""
    from .data import load
    from .inference import calibrate_xy

    loaded = load(path)
    items: list[Any] = loaded if isinstance(loaded, list) else [loaded]
    results = []
    for i, xy in enumerate(items):
        try:
            results.append(calibrate_xy(xy, **kw))
        except Exception as e:
            if len(items) == 1:
                raise
            raise CliError(f"{xy.name or f'recordings[{i}]'}: {e}") from e
    if as_json:
        dicts = [{"name": xy.name} | r.to_dict() for xy, r in zip(items, results, strict=True)]
        print(dumps_json(dicts[0] if len(dicts) == 1 else {"xy": dicts}))
        return 0
    for xy, r in zip(items, results, strict=True):
        if len(items) > 1:
            print(f"{xy.name}:")
        print(r.summary())
    return 0


def _fixed_arg(items) -> dict:
    """``--fix NAME=VALUE[+-SE]`` in lab units -> calibrate's ``fixed`` in SI."""
    from .effects import lab_units

    out = {}
    for item in items:
        name, sep, rest = item.partition("=")
        name = name.strip()
        value, _, se = rest.partition("+-")
        fac = lab_units(name)[0]
        try:
            v = float(value) / fac
            e = float(se) / fac if se else 0.0
        except ValueError:
            raise CliError(f"--fix takes NAME=VALUE or NAME=VALUE+-SE in lab units (e.g. "
                           f"tracking_var=0 or gamma=0.0095+-0.0003); got {item!r}") from None
        if not sep or not name:
            raise CliError(f"--fix takes NAME=VALUE; got {item!r}")
        out[name] = (v, e)
    return out


def diagnose_command(args) -> int:
    """``blurtrap diagnose``: diagnose, print the verdict and fit (or JSON), write the report."""
    from pathlib import Path

    from .data import holds_xy
    from .diagnostics import diagnose

    path = Path(args.manifest)
    _check_input_path(path)
    if holds_xy(path):
        raise CliError(f"{path}: diagnose does not take x/y recordings yet; use blurtrap "
                       "calibrate (principal axes, shared gamma), or in Python diagnose the "
                       "traces along the principal axes (XYRecording.project(result.phi))")
    report = _report_dir(args)
    d = diagnose(str(path), model=args.model, add=tuple(args.add), alpha=args.alpha)
    if report is not None:
        from ._report import write_diagnosis_report as write

        report = write(report, d, str(path))
    if args.json:
        out = d.to_dict() | ({"report": report} if report else {})
        out["gof"] = {k: out["gof"][k] for k in ("statistic", "dof", "p_value")}
        out["gof"]["p"] = out["gof"]["p_value"]
        print(dumps_json(out))
    else:
        print(d.summary())
        print()
        print(f"fit of the model {d.model}:")
        print(d.fit.summary())
        best = d.best
        if best is not None and best.fit is not None:  # add and refit, from the command line
            print(f"\nfit with {best.effect} added (model {best.fit.model}):")
            print(best.fit.summary())
    return _report_done(report, args.json)  # a diagnosis was made; adequacy is in the output


def _report_done(report, quiet: bool) -> int:
    """Where the report went; exit code 1 when one of its figures failed."""
    if report is not None:
        for f in report["failed"]:
            print(f"warning: report figure {f}", file=sys.stderr)
        if not quiet:
            print(f"report: {report['report']} ({len(report['files'])} files)")
    return 1 if report is not None and report["failed"] else 0


def _report_dir(args):
    """--report DIR, checked (and created) before any fit; None without --report."""
    if args.report is None:
        return None
    import matplotlib

    matplotlib.use("Agg")  # files only: never a GUI window from the command line
    from ._report import report_dir

    return report_dir(args.report)


def simulate_command(args) -> int:
    """``blurtrap simulate``: simulate recordings and write a manifest with their CSVs."""
    import numpy as np

    from .data import Recording, RecordingSet, save_manifest

    check_simulate(args)  # in the flags' units, before anything is simulated
    ks = [k * 1e-3 for k in args.k]
    if args.gamma is not None:
        gamma = args.gamma * 1e-6
    else:
        gamma = 6 * math.pi * args.viscosity * args.radius * 1e-6
    dt = 1.0 / args.fps
    ws = [w * 1e-3 for w in args.exposure_ms]
    for w in ws:
        if not (0 < w <= dt * (1 + 1e-3)):
            raise CliError(
                f"--exposure-ms {w * 1e3:g} must be > 0 and <= the frame interval "
                f"1000/fps = {dt * 1e3:.6g} ms")
    w_arr = np.minimum(np.asarray(ws), dt)
    powers = None
    if args.power_mw is not None:
        if len(args.power_mw) != len(ks):
            raise CliError(f"--power-mw needs one value per --k ({len(ks)}); "
                           f"got {len(args.power_mw)}")
        powers = [p * 1e-3 for p in args.power_mw]
    import jax

    from .simulate import simulate

    # an independent random stream per recording
    keys = jax.random.split(jax.random.key(args.seed), len(ks) * len(w_arr))
    keys = keys.reshape(len(ks), len(w_arr))
    x = simulate(np.asarray(ks)[:, None], gamma, w_arr[None, :], dt, args.frames,
                 key=keys, temperature=args.temperature,
                 method="exact_frames", tracking_std=args.tracking_nm * 1e-9)
    x = np.asarray(x, dtype=float)
    recs = []
    for i, k in enumerate(ks):
        for j, w in enumerate(w_arr):
            check_simulated_spread(x[i, j, 0], args.k[i], float(w) * 1e3, gamma * 1e6, args)
            recs.append(Recording(
                x[i, j, 0], frame_interval=dt, exposure=float(w), temperature=args.temperature,
                laser_power=None if powers is None else powers[i],
                name=f"k{k * 1e3:.4g}pN_per_nm_W{w * 1e3:.4g}ms",
                metadata={"simulated": True, "k_true_N_per_m": k, "gamma_true_N_s_per_m": gamma,
                          "tracking_std_m": args.tracking_nm * 1e-9, "seed": args.seed},
            ))
    from pathlib import Path

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = save_manifest(RecordingSet(recs), out / "manifest.json", "nm")
    if args.json:
        print(dumps_json({"manifest": str(written[0]), "files": [str(p) for p in written[1:]],
                          "n_recordings": len(recs), "n_frames": args.frames,
                          "gamma_pN_s_per_um": gamma * 1e6,
                          "k_pN_per_nm": list(args.k), "exposure_ms": list(args.exposure_ms),
                          "frame_interval_ms": dt * 1e3}))
    else:
        print(f"wrote {len(recs)} recording(s) x {args.frames} frames "
              f"(gamma = {gamma * 1e6:.4g} pN s/um, dt = {dt * 1e3:.4g} ms) to {written[0]}")
    return 0


def design_command(args) -> int:
    """``blurtrap design``: the recommended acquisition, printed (and plotted)."""
    import warnings

    from .design import NotIdentifiedError, design

    for text in check_design(args):  # in the flags' units, before any design is computed
        print(f"blurtrap design: warning: {text}", file=sys.stderr)
    k = tuple(v * 1e-3 for v in args.k)
    with warnings.catch_warnings():  # design's own (Python-worded) warning of --max-fps, said above
        warnings.filterwarnings("ignore", message=r"max_fps = .* is below", category=UserWarning)
        try:
            res = design(k=k[0] if len(k) == 1 else k,
                         gamma=None if args.gamma is None else args.gamma * 1e-6,
                         radius=None if args.radius_um is None else args.radius_um * 1e-6,
                         viscosity=args.viscosity, temperature=args.temperature,
                         max_fps=args.max_fps, min_exposure=args.min_exposure_ms * 1e-3,
                         dead_time=args.dead_time_ms * 1e-3, n_frames=args.frames,
                         total_time=args.total_s, tracking_std=args.tracking_nm * 1e-9,
                         photon_limited=args.photon_limited, target=args.target,
                         friction_error=(None if args.friction_error is None
                                         else args.friction_error / 100.0),
                         series=tuple(args.series), laser_powers=args.powers)
        except NotIdentifiedError as exc:
            raise CliError(not_identified_message(exc, args)) from exc
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        from .plotting import save

        save(res.plot(), args.plot)
    print(dumps_json(res.to_dict()) if args.json else res.summary())
    return 0
