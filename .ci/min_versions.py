"""Print ``name==floor`` for every runtime dependency in pyproject.toml's [project].dependencies.

The minimum-versions CI job installs exactly these pins, so the floors we declare are the
versions we test and cannot drift from pyproject.toml. Every runtime dependency must carry a
``>=`` floor; anything else is an error (exit 1) rather than a silently untested range.

Usage: python .ci/min_versions.py [path/to/pyproject.toml] > pins.txt
"""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

_REQ = re.compile(
    r"^\s*(?P<name>[A-Za-z0-9][A-Za-z0-9._-]*)\s*(?P<extras>\[[^\]]*\])?\s*"
    r"(?P<spec>[^;]*?)\s*(?:;\s*(?P<marker>.*))?$"
)


def floors(pyproject: Path) -> list[str]:
    deps = tomllib.loads(pyproject.read_text())["project"]["dependencies"]
    pins, errors = [], []
    for dep in deps:
        m = _REQ.match(dep)
        if m is None:
            errors.append(f"cannot parse {dep!r}")
            continue
        lows = [c.strip()[2:].strip() for c in m["spec"].split(",") if c.strip().startswith(">=")]
        if len(lows) != 1:
            errors.append(f"{dep!r} needs exactly one '>=' floor")
            continue
        marker = f"; {m['marker']}" if m["marker"] else ""
        pins.append(f"{m['name']}{m['extras'] or ''}=={lows[0]}{marker}")
    if errors:
        raise SystemExit("min_versions.py: " + "; ".join(errors))
    return pins


def main(argv: list[str]) -> int:
    path = Path(argv[1]) if len(argv) > 1 else Path(__file__).resolve().parents[1] / "pyproject.toml"
    print("\n".join(floors(path)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
