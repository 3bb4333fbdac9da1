"""Package layout: imports flow downward only (DESIGN section 4); import stays light."""

import ast
import pathlib
import subprocess
import sys

import pytest

PKG = pathlib.Path(__file__).resolve().parents[1] / "blurtrap"

# what each layer may import from blurtrap (besides itself); "_config" is the top-level helper,
# "_constants" the pure-Python constants every layer may use. data is numpy only, so it may not
# import physics (which imports jax).
ALLOWED = {
    "physics": {"_constants"},
    "effects": {"physics", "_constants"},
    "simulate": {"physics", "effects", "_constants"},
    "data": {"_constants"},
    "inference": {"physics", "effects", "data", "_config", "_constants"},
    "diagnostics": {"physics", "effects", "data", "inference", "simulate", "_config",
                    "_constants"},
    "design": {"physics", "effects", "data", "inference", "simulate", "_config", "_constants"},
    "sweeps": {"physics", "effects", "inference", "simulate", "_config", "_constants"},
    "plotting": {"physics", "effects", "data", "inference", "diagnostics", "design", "simulate",
                 "_config", "_constants"},
}


def blurtrap_imports(path: pathlib.Path, layer: str):
    tree = ast.parse(path.read_text())
    rel_parts = path.relative_to(PKG).parts
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == "blurtrap" and len(parts) > 1:
                    yield parts[1], node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                parts = (node.module or "").split(".")
                if parts[0] == "blurtrap":
                    if len(parts) > 1:
                        yield parts[1], node.lineno
                    else:
                        for alias in node.names:
                            yield alias.name, node.lineno
            else:
                # resolve relative import against the file's package
                base = list(rel_parts[:-1])
                up = node.level - 1
                if up > len(base):
                    continue
                base = base[: len(base) - up] if up else base
                target = base + ((node.module or "").split(".") if node.module else [])
                if target:
                    yield target[0], node.lineno
                else:
                    for alias in node.names:
                        yield alias.name, node.lineno


def _function_scope_lines(path: pathlib.Path) -> set[int]:
    """Line numbers of import statements inside a function body (lazy imports)."""
    lines = set()
    for fn in ast.walk(ast.parse(path.read_text())):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            lines |= {n.lineno for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))}
    return lines


#: a result object's ``plot()`` method may import plotting lazily, inside the method: the
#: layer itself never loads matplotlib (test_import_is_light) and plotting never imports it back
LAZY_PLOTTING = {"design", "inference"}


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_import_direction(layer):
    bad = []
    for path in (PKG / layer).rglob("*.py"):
        lazy = _function_scope_lines(path)
        for target, line in blurtrap_imports(path, layer):
            if target == "plotting" and layer in LAZY_PLOTTING and line in lazy:
                continue
            if target != layer and target not in ALLOWED[layer]:
                bad.append(f"{path.relative_to(PKG.parent)}:{line} imports blurtrap.{target}")
    assert not bad, "\n".join(bad)


def test_layout_matches_design():
    for sub in ALLOWED:
        assert (PKG / sub / "__init__.py").is_file(), sub
    assert (PKG / "cli.py").is_file()


def test_import_is_light():
    code = (
        "import sys, blurtrap; "
        "bad = [m for m in ('matplotlib', 'emcee', 'scipy', 'blurtrap.plotting') if m in sys.modules]; "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_import_does_not_change_precision_or_create_arrays():
    code = (
        "import jax; import blurtrap, sys; "
        "sys.exit(0 if (not jax.config.jax_enable_x64 and not jax.live_arrays()) else 1)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def _run(code):
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)


def test_constants_module_is_pure_python():
    """blurtrap._constants is what every layer may import: it must import nothing."""
    tree = ast.parse((PKG / "_constants.py").read_text())
    assert not [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))]


@pytest.mark.parametrize("stmt", ["import blurtrap.data", "import blurtrap",
                                  "from blurtrap import Recording, load_csv, from_arrays",
                                  "import blurtrap as bt; bt.load_manifest; bt.save_npz; bt.BOLTZMANN"])
def test_data_import_does_not_import_jax(stmt):
    """The data layer is numpy only (DESIGN section 4): loading recordings imports no jax."""
    out = _run(f"import sys; {stmt}; bad = [m for m in sys.modules if m.split('.')[0] "
               "in ('jax', 'jaxlib', 'equinox', 'optimistix')]; print(bad); sys.exit(1 if bad else 0)")
    assert out.returncode == 0, out.stdout + out.stderr


def test_lazy_top_level_names():
    """Every public name is reachable as before, is listed by dir() and __all__, and is the
    object of its subpackage; ``blurtrap.simulate`` stays the function even after the
    subpackage of that name was imported."""
    code = """
import sys, blurtrap as bt
names = bt.__all__
assert len(names) > 40 and set(names) <= set(dir(bt)), sorted(set(names) - set(dir(bt)))
assert 'jax' not in sys.modules
assert bt.__version__
for mod, name in [('data', 'Recording'), ('inference', 'calibrate'), ('_config', 'enable_x64'),
                  ('physics', 'blur_factor'), ('diagnostics', 'diagnose'), ('simulate', 'TrackingNoise')]:
    import importlib
    assert getattr(bt, name) is getattr(importlib.import_module('blurtrap.' + mod), name), name
for name in names:
    getattr(bt, name)
import jax
assert not jax.config.jax_enable_x64  # accessing the names changes no JAX setting
import blurtrap.simulate as s, blurtrap.simulate._core
assert callable(bt.simulate) and bt.simulate is s and not isinstance(s, type(sys))
assert bt.BOLTZMANN == 1.380649e-23 and bt.physics.BOLTZMANN is bt.BOLTZMANN
from blurtrap.physics import DEFAULT_TEMPERATURE
assert DEFAULT_TEMPERATURE == 295.0
try:
    bt.no_such_name
except AttributeError as e:
    assert 'no_such_name' in str(e)
else:
    raise AssertionError('no AttributeError')
"""
    out = _run(code)
    assert out.returncode == 0, out.stdout + out.stderr


def test_simulate_subpackage_imported_first_still_gives_the_function():
    out = _run("import blurtrap.simulate, blurtrap; assert callable(blurtrap.simulate), blurtrap.simulate")
    assert out.returncode == 0, out.stdout + out.stderr


# -- small rooms and clean boundaries (issue 16) ---------------------------------------------

MAX_FILE_LINES = 400
MAX_FUNCTION_LINES = 80


def _package_files():
    return sorted(PKG.rglob("*.py"))


def test_no_file_is_over_400_lines():
    """Every module of the package stays a small room: at most 400 lines (``wc -l``)."""
    long = [f"{p.relative_to(PKG.parent)}: {n} lines" for p in _package_files()
            if (n := len(p.read_text().splitlines())) > MAX_FILE_LINES]
    assert not long, "\n".join(long)


def function_code_lines(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Lines a function spans from its ``def`` (signature included, decorators not) to its
    last line, less the lines of its docstring: the code a reader has to hold in mind."""
    span = fn.end_lineno - fn.lineno + 1  # type: ignore[operator]
    first = fn.body[0]
    if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
            and isinstance(first.value.value, str)):
        span -= first.end_lineno - first.lineno + 1  # type: ignore[operator]
    return span


def test_function_code_lines_counts_code_not_docstrings():
    src = 'def f(a,\n      b):\n    """doc\n\n    more"""\n    x = 1\n    return x\n'
    fn = ast.parse(src).body[0]
    assert isinstance(fn, ast.FunctionDef) and function_code_lines(fn) == 4


def test_no_function_is_over_80_lines():
    """No function (or method, nested ones included) spans more than 80 lines of code, its
    docstring excluded (see ``function_code_lines``)."""
    long = []
    for p in _package_files():
        for fn in ast.walk(ast.parse(p.read_text())):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = function_code_lines(fn)
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{p.relative_to(PKG.parent)}:{fn.lineno} {fn.name}: {n} lines")
    assert not long, "\n".join(long)


SUBPACKAGES = sorted(p.parent.name for p in PKG.glob("*/__init__.py"))

#: imports of another subpackage's private module that are allowed anyway, as (file,
#: imported dotted name): none. An entry must name a reason; the list must not go stale.
PRIVATE_IMPORT_ALLOWED: set[tuple[str, str]] = set()


def imported_names(path: pathlib.Path, source: str | None = None):
    """Every ``blurtrap...`` name a module imports, as a dotted path with relative imports
    resolved (``from ..inference._fit import chi2_sf`` -> ``blurtrap.inference._fit.chi2_sf``),
    function-scope (lazy) imports included."""
    package = list(path.relative_to(PKG.parent).parts[:-1])  # ['blurtrap', 'inference']
    tree = ast.parse(path.read_text() if source is None else source)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = base + (node.module.split(".") if node.module else [])
            for alias in node.names:
                yield ".".join([*module, alias.name]), node.lineno


def cross_private_imports(path: pathlib.Path, source: str | None = None):
    """(dotted name, line) of each import in ``path`` that reaches a private module or a
    private name of *another* subpackage.

    The rule: in ``blurtrap/A/...`` (or a top-level module such as ``cli.py``, for which every
    subpackage is another), importing ``blurtrap.B.X...`` with ``B != A`` a subpackage is
    allowed only when no part of ``X...`` starts with an underscore: use what ``B`` shares
    through its ``__init__`` or a non-underscore module (``blurtrap.inference.internal``).
    Top-level private modules (``blurtrap/_constants.py``, ``blurtrap/_config.py``, ...) are
    shared infrastructure and may be imported from anywhere (``test_import_direction`` still
    says which layer may use which)."""
    rel = path.relative_to(PKG).parts
    here = rel[0] if len(rel) > 1 else None
    for name, line in imported_names(path, source):
        parts = name.split(".")
        if len(parts) < 3 or parts[0] != "blurtrap" or parts[1] not in SUBPACKAGES:
            continue
        if parts[1] == here:
            continue
        if any(p.startswith("_") and not p.startswith("__") for p in parts[2:]):
            yield name, line


def test_cross_private_import_rule_sees_every_form():
    """The checker resolves relative, absolute, lazy and ``from package import _module``
    forms, and lets public names, top-level private modules and the own subpackage pass."""
    src = ("from ..inference._fit import chi2_sf\n"
           "import blurtrap.physics._blur\n"
           "from blurtrap.inference import _spectral\n"
           "from ..physics import _blur_factor\n"
           "def f():\n    from ..plotting._common import save\n"
           "from ..inference import calibrate\n"
           "from ..inference.internal import as_recordings\n"
           "from .._constants import BOLTZMANN\n"
           "from ._diagnose import diagnose\n"
           "from blurtrap.diagnostics._select import compare\n")
    probe = PKG / "diagnostics" / "_probe.py"  # never written: only its place in the package counts
    found = [name for name, _ in cross_private_imports(probe, src)]
    assert found == ["blurtrap.inference._fit.chi2_sf", "blurtrap.physics._blur",
                     "blurtrap.inference._spectral", "blurtrap.physics._blur_factor",
                     "blurtrap.plotting._common.save"]
    top = [name for name, _ in cross_private_imports(PKG / "_probe.py", "from .diagnostics._select import compare\n")]
    assert top == ["blurtrap.diagnostics._select.compare"]


def test_no_import_of_another_subpackages_private_module():
    """No module imports another subpackage's private module or private name (issue 16:
    clean boundaries); see ``cross_private_imports`` for the rule and
    ``PRIVATE_IMPORT_ALLOWED`` for the few left to another change."""
    bad, used = [], set()
    for path in _package_files():
        rel = str(path.relative_to(PKG.parent))
        for name, line in cross_private_imports(path):
            if (rel, name) in PRIVATE_IMPORT_ALLOWED:
                used.add((rel, name))
            else:
                bad.append(f"{rel}:{line} imports {name}")
    assert not bad, "\n".join(bad)
    assert used == PRIVATE_IMPORT_ALLOWED, f"stale allow-list entries: {PRIVATE_IMPORT_ALLOWED - used}"
