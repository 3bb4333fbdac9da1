"""Package layout: imports flow downward only (DESIGN section 4); import stays light."""

import ast
import pathlib
import subprocess
import sys

import pytest

PKG = pathlib.Path(__file__).resolve().parents[1] / "blurtrap"

# what each layer may import from blurtrap (besides itself); "_config" is the top-level helper
ALLOWED = {
    "physics": set(),
    "simulate": {"physics"},
    "data": {"physics"},
    "inference": {"physics", "data", "_config"},
    "diagnostics": {"physics", "data", "inference", "simulate", "_config"},
    "plotting": {"physics", "data", "inference", "diagnostics", "simulate", "_config"},
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


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_import_direction(layer):
    bad = []
    for path in (PKG / layer).rglob("*.py"):
        for target, line in blurtrap_imports(path, layer):
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
