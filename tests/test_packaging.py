"""Packaging: the command's entry points, the licence, and that every import is declared.

Third-party modules imported anywhere in ``blurtrap/`` must be runtime dependencies in
pyproject.toml's [project].dependencies, or optional extras that are imported lazily (inside
a function, with a clear ImportError), listed in ``OPTIONAL_LAZY`` below.
"""

import ast
import logging
import re
import subprocess
import sys
import tomllib
import warnings
from importlib.metadata import version
from pathlib import Path

import jax
import numpy as np

import blurtrap

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "blurtrap"
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())

# import name -> the extra of [project.optional-dependencies] that provides it
OPTIONAL_LAZY = {"arviz": "arviz", "pandas": "pandas", "h5py": "h5py", "nptdms": "tdms",
                 "xarray": "xarray"}
# import name -> distribution name, where they differ
DIST_NAME = {"nptdms": "npTDMS"}


def _run(*args):
    return subprocess.run([sys.executable, "-m", "blurtrap", *args], capture_output=True,
                          text=True, timeout=300)


def _req_name(req: str) -> str:
    return re.split(r"[\s\[<>=!~;]", req.strip(), maxsplit=1)[0].lower().replace("_", "-")


def test_version_flag():
    out = _run("--version")
    assert out.returncode == 0, out.stderr
    assert out.stdout == f"blurtrap {version('blurtrap')}\n"
    assert blurtrap.__version__ == version("blurtrap")


def test_console_script_version():
    script = Path(sys.executable).with_name("blurtrap")
    assert script.exists(), f"the `blurtrap` command is not installed next to {sys.executable}"
    out = subprocess.run([str(script), "--version"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout == f"blurtrap {version('blurtrap')}\n"


def test_python_m_blurtrap_is_the_command():
    out = _run("--help")
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("usage: blurtrap ")
    for command in ("demo", "simulate", "calibrate", "diagnose"):
        assert command in out.stdout
    bad = _run("no-such-command")
    assert bad.returncode == 2 and "blurtrap: error:" in bad.stderr


def test_license_file_matches_pyproject():
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License")
    assert "Copyright (c) 2026 blurtrap developers" in text
    project = PYPROJECT["project"]
    assert project["license"] == {"text": "MIT"}
    assert "License :: OSI Approved :: MIT License" in project["classifiers"]


def _imports(path: Path):
    """(top-level module, lazy) for every absolute import in ``path``; lazy = inside a def."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out = []

    def visit(node, lazy):
        for child in ast.iter_child_nodes(node):
            inner = lazy or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                out.extend((a.name.split(".")[0], inner) for a in child.names)
            elif isinstance(child, ast.ImportFrom) and child.level == 0 and child.module:
                out.append((child.module.split(".")[0], inner))
            visit(child, inner)

    visit(tree, False)
    return out


def test_every_third_party_import_is_declared():
    runtime = {_req_name(r) for r in PYPROJECT["project"]["dependencies"]}
    extras = {name: {_req_name(r) for r in reqs}
              for name, reqs in PYPROJECT["project"]["optional-dependencies"].items()}
    seen, problems = set(), []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT)
        for mod, lazy in _imports(path):
            if mod in sys.stdlib_module_names or mod in ("blurtrap", "__future__"):
                continue
            seen.add(mod)
            dist = DIST_NAME.get(mod, mod).lower().replace("_", "-")
            if dist in runtime:
                continue
            if mod not in OPTIONAL_LAZY:
                problems.append(f"{rel}: imports {mod}, which is not in [project].dependencies")
            elif not lazy:
                problems.append(f"{rel}: optional {mod} is imported at module level")
            elif dist not in extras.get(OPTIONAL_LAZY[mod], set()):
                problems.append(f"{rel}: {mod} is not in the [{OPTIONAL_LAZY[mod]}] extra")
    assert not problems, "\n".join(problems)
    assert {"jax", "equinox", "optimistix", "numpy"} <= seen  # the walk found the imports


def test_no_redundant_or_test_only_runtime_dependencies():
    runtime = {_req_name(r) for r in PYPROJECT["project"]["dependencies"]}
    assert "jaxlib" not in runtime  # jax pins its own jaxlib
    assert not runtime & {"pytest", "pytest-xdist", "hypothesis", "scipy", "mpmath"}
    assert {"tqdm", "jaxtyping"} <= runtime


def test_min_versions_pins_every_runtime_dependency():
    out = subprocess.run([sys.executable, str(ROOT / ".ci" / "min_versions.py")],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    pins = out.stdout.split()
    deps = PYPROJECT["project"]["dependencies"]
    assert [_req_name(p) for p in pins] == [_req_name(d) for d in deps]
    for pin, dep in zip(pins, deps, strict=True):
        floor = re.search(r">=\s*([^,;\s]+)", dep).group(1)
        assert pin.endswith(f"=={floor}"), (pin, dep)


def test_posterior_progress_bar_uses_tqdm(caplog, capsys):
    """emcee's progress=True needs tqdm (a declared dependency): no 'install tqdm' warning,
    and a bar on stderr."""
    x = blurtrap.simulate(2e-5, 8.5e-9, 1 / 1500, 1 / 1500, 4096, key=jax.random.key(5),
                          method="exact_frames", tracking_std=2e-9)
    rec = blurtrap.Recording(np.asarray(x, dtype=float).reshape(-1), frame_interval=1 / 1500,
                             exposure=1 / 1500)
    with caplog.at_level(logging.WARNING), warnings.catch_warnings():
        warnings.simplefilter("ignore", blurtrap.ShortChainWarning)  # a deliberately short chain
        blurtrap.sample_posterior(rec, n_walkers=8, n_steps=30, progress=True)
    assert "install the tqdm library" not in caplog.text
    assert "30/30" in capsys.readouterr().err
