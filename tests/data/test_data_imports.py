"""Layering of blurtrap.data: numpy only; of blurtrap, only the pure-Python blurtrap._constants
(DESIGN sec. 4: blurtrap.physics imports jax, so data may not import it)."""

import ast
from pathlib import Path

import pytest

import blurtrap.data

DATA_DIR = Path(blurtrap.data.__file__).parent
FILES = sorted(DATA_DIR.glob("*.py"))
FORBIDDEN_TOP = {"jax", "jaxlib", "equinox", "optimistix", "matplotlib", "emcee"}
ALLOWED_RELATIVE = {"_constants"}  # from .._constants import ...


def imports(path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield 0, a.name
        elif isinstance(node, ast.ImportFrom):
            yield node.level, node.module or ""


def test_files_found():
    assert {p.name for p in FILES} >= {"__init__.py", "_recording.py", "_csv.py"}


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_no_forbidden_imports(path):
    for level, module in imports(path):
        top = module.split(".")[0]
        if level == 0:
            assert top not in FORBIDDEN_TOP, f"{path.name} imports {module}"
            if top == "blurtrap":
                assert module.split(".")[1] == "_constants", f"{path.name} imports {module}"
        elif level >= 2:
            assert top in ALLOWED_RELATIVE, f"{path.name} imports {'.' * level}{module}"


def test_public_names():
    for name in [
        "Recording",
        "RecordingSet",
        "load",
        "load_csv",
        "load_manifest",
        "save_manifest",
        "load_npz",
        "save_npz",
        "from_arrays",
    ]:
        assert hasattr(blurtrap.data, name)
