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
