"""The ``blurtrap`` command line (skeleton; subcommands land with their capabilities)."""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="blurtrap", description=__doc__)
    p.add_argument("--debug", action="store_true", help="show full tracebacks on error")
    sub = p.add_subparsers(dest="command", required=True)
    d = sub.add_parser("demo", help="simulate the paper's experiment and calibrate it every way")
    d.add_argument("--out", default="blurtrap-demo", help="output folder (default ./blurtrap-demo)")
    d.add_argument("--json", action="store_true", help="print one JSON object")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from . import enable_x64

    enable_x64()
    try:
        if args.command == "demo":
            from ._demo import run_demo

            return run_demo(args)
    except Exception as exc:  # one clear line, not a traceback
        if args.debug:
            raise
        print(f"blurtrap {args.command}: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
