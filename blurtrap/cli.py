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


class CliError(Exception):
    """A user error with a message that needs no traceback."""


def build_parser() -> argparse.ArgumentParser:
    """The parser of every ``blurtrap`` command (built in :mod:`blurtrap._cli_parser`)."""
    from ._cli_parser import build_parser as build

    return build(__doc__)


# ------------------------------------------------------------------------------------------
# calibrate
# ------------------------------------------------------------------------------------------
def format_result(result) -> str:
    """A readable lab-unit table of a ``CalibrationResult`` (its ``summary()``)."""
    return result.summary()


# ------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2), already printed
        return int(exc.code) if isinstance(exc.code, int) else 1
    import os

    from . import enable_compilation_cache, enable_x64
    from ._config import faster_compilation

    faster_compilation()  # before the first computation: XLA reads its flags once
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
            from ._cli_commands import simulate_command

            return simulate_command(args)
        if args.command == "calibrate":
            from ._cli_commands import calibrate_command

            return calibrate_command(args)
        if args.command == "diagnose":
            from ._cli_commands import diagnose_command

            return diagnose_command(args)
        if args.command == "design":
            from ._cli_commands import design_command

            return design_command(args)
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
