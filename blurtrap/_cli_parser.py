"""The argument parser of the ``blurtrap`` command (:func:`blurtrap.cli.build_parser`): one
sub-parser per command, options in lab units."""

from __future__ import annotations

import argparse

_METHODS = ("auto", "likelihood", "psd", "variance_vs_exposure", "variance_vs_power",
            "equipartition", "allan")
_K_MODES = ("shared", "per_recording", "per_power", "linear_power")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``blurtrap <cmd>: error: ...``, exit 2)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


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


def _model_arg(text: str) -> str:
    """argparse type of ``--model``: a named model, optionally ``+effect``s (checked here, so a
    typo is a usage error before anything is loaded or fitted)."""
    from .inference import get_model

    try:
        get_model(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def build_parser(description: str | None = None) -> argparse.ArgumentParser:
    """The parser of every ``blurtrap`` command (`description`: the ``--help`` text)."""
    p = _Parser(prog="blurtrap", description=description,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--debug", action="store_true", help="show full tracebacks on error")
    from . import __version__
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    _add_demo_parser(sub)
    _add_simulate_parser(sub)
    _add_calibrate_parser(sub)
    _add_diagnose_parser(sub)
    _add_design_parser(sub)
    return p


def _add_demo_parser(sub):
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


def _add_simulate_parser(sub):
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


def _add_calibrate_parser(sub):
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
    c.add_argument("--steps", type=_int_at_least(10), default=None, metavar="N",
                   help="emcee steps for --posterior (>= 10; default: 2000, extended until the "
                   "chain holds 50 autocorrelation times, at most 20000)")
    c.add_argument("--walkers", type=_int_at_least(2, even=True), default=32, metavar="N",
                   help="emcee walkers for --posterior (even, >= 2 x the number of "
                   "parameters; default 32)")
    c.add_argument("--json", action="store_true",
                   help="print the result as one JSON object (SI units, to_dict())")
    _add_report(c)
    _add_debug(c)


def _add_diagnose_parser(sub):
    g = sub.add_parser(
        "diagnose", help="goodness of fit and ranked missing effects",
        description="Fit the model, test whether it describes the data, and rank the "
        "physical effects that may be missing (canonical effect names), with the evidence.")
    g.add_argument("manifest", metavar="MANIFEST", help="manifest JSON (or .npz)")
    g.add_argument("--model", type=_model_arg, default=None,
                   help="starting model: naive, blur, standard, optionally with effects added "
                   "by '+' (e.g. standard+drift); default: the recordings' detector (standard "
                   "for a camera, photodiode_aa for a photodiode with anti-aliasing)")
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


def _power_list(text: str) -> tuple:
    """argparse type of ``design --powers``: comma-separated numbers (checked further by
    ``design``: at least 2 distinct, all > 0)."""
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be comma-separated numbers (multiples of the power --k is at), e.g. "
            f"0.5,1,2; got {text!r}") from None


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
    d.add_argument("--target", choices=("k", "gamma", "both", "determinant",
                                        "force_sensitivity"), default="k",
                   help="what to minimise the SE of (default k; determinant: of k and gamma "
                   "together; force_sensitivity: Rf of a passive calibration in volts, needs "
                   "--friction-error)")
    d.add_argument("--friction-error", type=float, default=None, metavar="PCT",
                   help="the friction is known from the bead (Stokes) to this relative error "
                   "[%%] (0 = exactly) instead of fitted; makes dt >> tau designs possible")
    d.add_argument("--series", type=int, nargs="+", default=(1, 2, 3), metavar="N",
                   help="numbers of exposures to try at a common frame interval (default "
                   "1 2 3; 1 = one recording)")
    d.add_argument("--powers", type=_power_list, default=None, metavar="P1,P2,...",
                   help="available laser powers as multiples of the power --k is at, e.g. "
                   "0.5,1,2 (k = c P): adds power series and the best single power to the "
                   "candidates (fit such a series with calibrate --k-mode linear_power)")
    d.add_argument("--plot", metavar="PNG", default=None,
                   help="also write the predicted-SE figure to this PNG file")
    d.add_argument("--json", action="store_true", help="print one JSON object (SI units)")
    _add_debug(d)
