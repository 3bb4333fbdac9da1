"""The ``blurtrap`` command line: calibrate optical traps from blurred, sampled recordings.

Lab units on the command line and in the output (nm, pN/nm, pN s/um, ms, Hz, um^2/s, mW);
SI inside. Errors are one line ``blurtrap <command>: error: ...`` with a non-zero exit code
(``--debug`` shows the traceback).
"""

from __future__ import annotations

import argparse
import json
import math
import sys

_METHODS = ("auto", "likelihood", "psd", "variance_vs_exposure", "variance_vs_power",
            "equipartition", "allan")
_K_MODES = ("shared", "per_recording", "per_power", "linear_power")



def _finite_or_none(obj):
    """A copy of ``obj`` that strict JSON can hold: non-finite floats become ``None`` (JSON
    has no NaN or Infinity; Python's json would print bare ``NaN`` literals, which strict
    parsers reject), NumPy scalars and arrays become Python numbers and lists."""
    if isinstance(obj, dict):
        return {str(k) if not isinstance(k, str) else k: _finite_or_none(v)
                for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if isinstance(obj, (str, bool)) or obj is None:
        return obj
    if isinstance(obj, int):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    tolist = getattr(obj, "tolist", None)  # NumPy / JAX scalars and arrays
    if callable(tolist):
        return _finite_or_none(tolist())
    try:
        return _finite_or_none(float(obj))
    except (TypeError, ValueError):
        return str(obj)


def dumps_json(obj) -> str:
    """One line of strict JSON (RFC 8259): non-finite floats are written as ``null``."""
    return json.dumps(_finite_or_none(obj), allow_nan=False)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``blurtrap <cmd>: error: ...``, exit 2)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


class CliError(Exception):
    """A user error with a message that needs no traceback."""


def _int_at_least(low: int, even: bool = False):
    """argparse type: an integer >= ``low`` (and even), checked before any work is done."""

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer; got {text!r}") from None
        if v < low or (even and v % 2):
            raise argparse.ArgumentTypeError(
                f"must be {'an even' if even else 'an'} integer >= {low}; got {v}")
        return v

    return parse


def _add_debug(p):
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                   help="show full tracebacks on error")


def _add_report(p, what=""):
    p.add_argument("--report", metavar="DIR", default=None,
                   help="also write DIR/report.md (lab units), the JSON result and PNG figures "
                   f"(spectrum with fit and residuals, frame histogram per recording{what}); "
                   "DIR is created if missing; files of those names in DIR are overwritten, "
                   "other files are left alone")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="blurtrap", description=__doc__,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--debug", action="store_true", help="show full tracebacks on error")
    from . import __version__
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    d = sub.add_parser(
        "demo", help="simulate the paper's experiment and calibrate it every way",
        description="Simulate Wong & Halvorsen (2006): a 3.063 um bead at 4 laser powers "
        "filmed with a series of exposures by a ~1500 fps camera with 2 nm tracking error; "
        "calibrate it every way (naive equipartition, variance vs exposure and vs power, "
        "blocked PSD with naive / naive-aliased / blur-corrected models, exact likelihood, "
        "posterior when available); print k and gamma against the truth; write PNG figures "
        "and report.md.")
    d.add_argument("--out", default="blurtrap-demo", metavar="DIR",
                   help="output folder for report.md, results.json and figures "
                   "(default ./blurtrap-demo)")
    d.add_argument("--json", action="store_true",
                   help="print one JSON object (no progress lines)")
    d.add_argument("--quick", action="store_true",
                   help="small sizes, no exact likelihood or posterior (a fast check)")
    d.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    _add_debug(d)

    s = sub.add_parser(
        "simulate", help="simulate recordings and write a manifest + CSV files",
        description="Simulate blurred, sampled bead positions (exact frame sampler) for every "
        "combination of --k and --exposure-ms and write DIR/manifest.json with one CSV per "
        "recording (positions in nm).")
    s.add_argument("--k", type=float, nargs="+", required=True, metavar="PN_PER_NM",
                   help="trap stiffness(es) [pN/nm]")
    g = s.add_mutually_exclusive_group(required=True)
    g.add_argument("--gamma", type=float, metavar="PN_S_PER_UM",
                   help="friction coefficient [pN s/um]")
    g.add_argument("--radius", type=float, metavar="UM",
                   help="bead radius [um]; gamma = 6 pi eta r")
    s.add_argument("--viscosity", type=float, default=0.00095, metavar="PA_S",
                   help="viscosity for --radius [Pa s] (default 0.00095, water at 295 K)")
    s.add_argument("--exposure-ms", type=float, nargs="+", required=True, metavar="MS",
                   help="exposure time(s) W [ms], each <= 1000/fps")
    s.add_argument("--fps", type=float, default=1500.0, help="frame rate [Hz] (default 1500)")
    s.add_argument("--frames", type=int, default=32768, help="frames per recording "
                   "(default 32768)")
    s.add_argument("--tracking-nm", type=float, default=0.0, metavar="NM",
                   help="tracking-error standard deviation [nm] (default 0)")
    s.add_argument("--temperature", type=float, default=295.0, metavar="K",
                   help="temperature [K] (default 295)")
    s.add_argument("--power-mw", type=float, nargs="+", metavar="MW",
                   help="laser power [mW] for each --k (stored in the manifest)")
    s.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    _add_debug(s)

    c = sub.add_parser(
        "calibrate", help="calibrate k, gamma, D, eps^2 from a manifest (or NPZ/CSV)",
        description="Calibrate the recordings named by MANIFEST and print k, gamma, D and "
        "eps^2 with standard errors in lab units (or --json: the result in SI units).")
    c.add_argument("manifest", metavar="MANIFEST",
                   help="manifest JSON (or .npz); x/y entries (t_s,x_nm,y_nm CSVs) run "
                   "calibrate_xy")
    c.add_argument("--method", choices=_METHODS, default="auto",
                   help="estimator (default auto: the most informative the data allow)")
    c.add_argument("--model", type=_model_arg, default=None,
                   help="trap model: standard (default: blur + aliasing + tracking noise, or "
                   "what the manifest's detector implies), blur, naive, naive_aliased, "
                   "optionally with effects added by '+', e.g. standard+drift or "
                   "standard+drift+line_noise")
    c.add_argument("--k-mode", choices=_K_MODES, default=None,
                   help="how k is shared across recordings (default: per power when powers "
                   "differ, k = cP for variance_vs_power)")
    c.add_argument("--likelihood", choices=("auto", "exact", "whittle"), default="auto",
                   help="likelihood for --method likelihood (default auto)")
    c.add_argument("--n-blocks", type=int, default=None,
                   help="blocks for --method psd (default 128, >= 64 frames each)")
    c.add_argument("--f-range", type=float, nargs=2, default=None, metavar=("FMIN", "FMAX"),
                   help="frequency range fitted by the spectral methods [Hz]")
    c.add_argument("--friction", choices=("free", "stokes"), default=None,
                   help="friction: fitted (free) or Stokes from the manifest's bead_radius_m "
                   "(default: the manifest's 'friction', else free)")
    c.add_argument("--exclude", type=float, nargs=2, action="append", default=None,
                   metavar=("F_LOW", "F_HIGH"),
                   help="exclude this band [Hz] from the spectral fit (repeatable)")
    c.add_argument("--fix", action="append", default=None, metavar="NAME=VALUE",
                   help="hold a parameter at a value in lab units (k in pN/nm, gamma in "
                   "pN s/um, tracking_var in nm^2, ...), optionally +-SE: gamma=0.0095+-0.0003 "
                   "(repeatable)")
    c.add_argument("--lines", choices=("auto", "keep"), default="auto",
                   help="auto (default): find strong narrow lines (drives, mains) and "
                   "subtract them before fitting; keep: fit the trace as it is")
    c.add_argument("--diffusion", type=float, default=None, metavar="UM2_PER_S",
                   help="known D [um^2/s]: blur-corrected --method equipartition, and the "
                        "fallback of --method auto when frames carry no temporal information")
    c.add_argument("--posterior", action="store_true",
                   help="also sample the posterior with emcee (medians, 68 %%/95 %% intervals)")
    c.add_argument("--steps", type=_int_at_least(10), default=2000, metavar="N",
                   help="emcee steps for --posterior (>= 10; default 2000)")
    c.add_argument("--walkers", type=_int_at_least(2, even=True), default=32, metavar="N",
                   help="emcee walkers for --posterior (even, >= 2 x the number of "
                   "parameters; default 32)")
    c.add_argument("--json", action="store_true",
                   help="print the result as one JSON object (SI units, to_dict())")
    _add_report(c)
    _add_debug(c)

    g = sub.add_parser(
        "diagnose", help="goodness of fit and ranked missing effects",
        description="Fit the model, test whether it describes the data, and rank the "
        "physical effects that may be missing (canonical effect names), with the evidence.")
    g.add_argument("manifest", metavar="MANIFEST", help="manifest JSON (or .npz)")
    g.add_argument("--model", type=_model_arg, default="standard",
                   help="starting model: naive, blur, standard (default), optionally with "
                   "effects added by '+' (e.g. standard+drift)")
    g.add_argument("--add", nargs="+", default=(), metavar="EFFECT",
                   help="effects added to the model before diagnosing (canonical names: "
                   "motion_blur, aliasing, tracking_noise, drift, line_noise, exposure_kernel, "
                   "detector_filter, hydrodynamics, power_offset, laser_heating; anharmonicity "
                   "and timing_jitter are tested, not added)")
    g.add_argument("--alpha", type=float, default=0.05,
                   help="family-wise false-alarm rate (default 0.05)")
    g.add_argument("--json", action="store_true", help="print one JSON object")
    _add_report(g, "; the ranking; residuals before/after adding the best candidate")
    _add_debug(g)
    _add_design_parser(sub)
    return p


def _add_design_parser(sub):
    d = sub.add_parser(
        "design", help="recommend frame rate, exposures and record length (Fisher information)",
        description="Recommend an acquisition (frame interval, exposure series, frames) that "
        "minimises the predicted standard error of k and/or gamma, for a bead in a trap of "
        "expected stiffness, and compare it with the paper's series and your current design. "
        "Lab units on the command line.")
    d.add_argument("--k", type=float, nargs="+", required=True, metavar="PN_PER_NM",
                   help="expected stiffness [pN/nm], or a range K_MIN K_MAX (worst case)")
    fr = d.add_mutually_exclusive_group(required=True)
    fr.add_argument("--radius-um", type=float, metavar="UM", help="bead radius [um] (Stokes)")
    fr.add_argument("--gamma", type=float, metavar="PN_S_PER_UM", help="friction [pN s/um]")
    d.add_argument("--viscosity", type=float, default=None, metavar="PA_S",
                   help="viscosity [Pa s] for --radius-um (default water at --temperature)")
    d.add_argument("--temperature", type=float, default=295.0, metavar="K",
                   help="temperature [K] (default 295)")
    d.add_argument("--max-fps", type=float, required=True, help="fastest frame rate [Hz]")
    d.add_argument("--min-exposure-ms", type=float, default=1e-3, metavar="MS",
                   help="shortest exposure [ms] (default 0.001)")
    d.add_argument("--dead-time-ms", type=float, default=0.0, metavar="MS",
                   help="camera dead time [ms]: W <= dt - dead time (default 0)")
    n = d.add_mutually_exclusive_group(required=True)
    n.add_argument("--frames", type=int, help="frames per recording")
    n.add_argument("--total-s", type=float, metavar="S",
                   help="total recording time [s] shared by all recordings")
    d.add_argument("--tracking-nm", type=float, default=0.0, metavar="NM",
                   help="tracking-error rms [nm] (default 0)")
    d.add_argument("--photon-limited", action="store_true",
                   help="tracking error grows as sqrt(1/W) below the reference exposure")
    d.add_argument("--target", choices=("k", "gamma", "both"), default="k",
                   help="what to minimise the SE of (default k)")
    d.add_argument("--series", type=int, nargs="+", default=(1, 2, 3), metavar="N",
                   help="numbers of exposures to try at a common frame interval (default "
                   "1 2 3; 1 = one recording)")
    d.add_argument("--plot", metavar="PNG", default=None,
                   help="also write the predicted-SE figure to this PNG file")
    d.add_argument("--json", action="store_true", help="print one JSON object (SI units)")
    _add_debug(d)


def _design(args) -> int:
    from .design import design

    if len(args.k) not in (1, 2):
        raise CliError(f"--k takes one stiffness or a range K_MIN K_MAX [pN/nm]; got {args.k}")
    k = tuple(v * 1e-3 for v in args.k)
    res = design(k=k[0] if len(k) == 1 else k,
                 gamma=None if args.gamma is None else args.gamma * 1e-6,
                 radius=None if args.radius_um is None else args.radius_um * 1e-6,
                 viscosity=args.viscosity, temperature=args.temperature,
                 max_fps=args.max_fps, min_exposure=args.min_exposure_ms * 1e-3,
                 dead_time=args.dead_time_ms * 1e-3, n_frames=args.frames,
                 total_time=args.total_s, tracking_std=args.tracking_nm * 1e-9,
                 photon_limited=args.photon_limited, target=args.target,
                 series=tuple(args.series))
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        from .plotting import save

        save(res.plot(), args.plot)
    print(dumps_json(res.to_dict()) if args.json else res.summary())
    return 0


# ------------------------------------------------------------------------------------------
# simulate
# ------------------------------------------------------------------------------------------
def _simulate(args) -> int:
    import numpy as np

    from .data import Recording, RecordingSet, save_manifest

    if args.frames < 16:
        raise CliError(f"--frames must be >= 16; got {args.frames}")
    if args.fps <= 0:
        raise CliError(f"--fps must be > 0 Hz; got {args.fps:g}")
    ks = [k * 1e-3 for k in args.k]
    if any(not (k > 0) for k in ks):
        raise CliError(f"--k must be > 0 pN/nm; got {args.k}")
    if args.gamma is not None:
        gamma = args.gamma * 1e-6
        if not gamma > 0:
            raise CliError(f"--gamma must be > 0 pN s/um; got {args.gamma:g}")
    else:
        if not args.radius > 0:
            raise CliError(f"--radius must be > 0 um; got {args.radius:g}")
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


# ------------------------------------------------------------------------------------------
# calibrate
# ------------------------------------------------------------------------------------------
def format_result(result) -> str:
    """A readable lab-unit table of a ``CalibrationResult`` (its ``summary()``)."""
    return result.summary()


def _model_arg(text: str) -> str:
    """argparse type of ``--model``: a named model, optionally ``+effect``s (checked here, so a
    typo is a usage error before anything is loaded or fitted)."""
    from .inference import get_model

    try:
        get_model(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


# ------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2), already printed
        return int(exc.code) if isinstance(exc.code, int) else 1
    import os

    from . import enable_compilation_cache, enable_x64

    enable_x64()
    if not os.environ.get("BLURTRAP_NO_CACHE"):
        try:  # compiled programs on disk: the second run of a command skips compilation
            enable_compilation_cache()
        except OSError:  # pragma: no cover - read-only home: run without the cache
            pass
    debug = getattr(args, "debug", False)
    try:
        if args.command == "demo":
            import matplotlib

            matplotlib.use("Agg")  # files only: never a GUI window from the command line
            from ._demo import run_demo

            if not getattr(args, "json", False):
                return run_demo(args)
            # the demo prints Python's json (NaN literals for e.g. the naive gamma): re-emit
            # it as strict JSON
            import contextlib
            import io

            buf = io.StringIO()
            with contextlib.redirect_stdout(buf):
                rc = run_demo(args)
            for line in buf.getvalue().splitlines():
                print(dumps_json(json.loads(line)) if line.startswith("{") else line)
            return rc
        if args.command == "simulate":
            return _simulate(args)
        if args.command == "calibrate":
            from ._cli_commands import calibrate_command

            return calibrate_command(args)
        if args.command == "diagnose":
            from ._cli_commands import diagnose_command

            return diagnose_command(args)
        if args.command == "design":
            return _design(args)
        raise CliError(f"unknown command {args.command!r}")  # pragma: no cover
    except BrokenPipeError:  # output piped into e.g. `head`: not an error
        import os

        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):  # pragma: no cover
            pass
        return 0
    except KeyboardInterrupt:  # pragma: no cover
        print(f"blurtrap {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # one clear line, not a traceback
        if debug:
            raise
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"blurtrap {args.command}: error: {msg}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
