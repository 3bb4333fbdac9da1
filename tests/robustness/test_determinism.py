"""Determinism: the same inputs and key/seed give identical bytes, and no global RNG state is
used or changed.

- a static scan of the package for numpy/stdlib global-RNG calls (``np.random.normal`` ...);
- ``simulate`` with the same key twice (with ``np.random.seed`` changed in between) gives the
  same bytes, and another key gives other numbers (so the key is really what is used).

The same checks for ``calibrate``, ``calibrate_batch`` and ``sample_posterior`` live in
``test_no_recompile.py``: they reuse the call that warms up the compile counter there, so the
expensive programs are traced once.
"""

import ast
from pathlib import Path

import jax
import numpy as np
import pytest
from _simconfig import sim  # the call (and compiled programs) of test_no_recompile.py

import blurtrap as bt

PKG = Path(bt.__file__).parent
# constructors of *local* generators: fine (explicitly seeded or fresh objects)
LOCAL_RNG = {"default_rng", "Generator", "SeedSequence", "PCG64", "PCG64DXSM", "Philox", "SFC64",
             "MT19937", "BitGenerator"}


def _dotted(node):
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
    return ".".join(reversed(parts))


def global_rng_calls(path: Path):
    """(line, call) of every call that touches numpy's or the stdlib's global RNG."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    stdlib_random = any(
        isinstance(n, ast.Import) and any(a.name == "random" for a in n.names)
        or isinstance(n, ast.ImportFrom) and n.module == "random"
        for n in ast.walk(tree)
    )
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        name = _dotted(node.func)
        parts = name.split(".")
        if len(parts) >= 3 and parts[-3] in ("np", "numpy") and parts[-2] == "random":
            if parts[-1] in LOCAL_RNG:
                continue
            if parts[-1] == "RandomState" and node.args:  # seeded, local RandomState
                continue
            found.append((node.lineno, name))
        elif stdlib_random and parts[0] == "random":
            found.append((node.lineno, name))
    return found


def test_scanner_finds_global_rng_calls(tmp_path):
    """The scan itself must be able to fail."""
    p = tmp_path / "m.py"
    p.write_text("import numpy as np\nimport random\n"
                 "a = np.random.normal(size=3)\nnp.random.seed(1)\nb = random.random()\n"
                 "r = np.random.RandomState()\ng = np.random.default_rng(0)\n"
                 "s = np.random.RandomState(3)\n")
    assert [c for _, c in global_rng_calls(p)] == [
        "np.random.normal", "np.random.seed", "random.random", "np.random.RandomState"]


def test_package_uses_no_global_rng():
    hits = {str(f.relative_to(PKG.parent)): global_rng_calls(f) for f in sorted(PKG.rglob("*.py"))}
    hits = {f: h for f, h in hits.items() if h}
    assert hits == {}, f"global RNG calls in the package: {hits}"


@pytest.mark.parametrize("method, kw", [("exact_frames", {}), ("exact", {"substeps": 8})])
def test_simulate_same_key_same_bytes_and_no_global_rng(method, kw):
    np.random.seed(1)
    state = np.random.get_state()[1].copy()
    a = sim(jax.random.key(0), method=method, **kw)
    assert np.array_equal(np.random.get_state()[1], state)  # global state untouched
    np.random.seed(2)  # a different global seed must change nothing
    b = sim(jax.random.key(0), method=method, **kw)
    assert a == b
    c = sim(jax.random.key(1), method=method, **kw)
    assert c != a
