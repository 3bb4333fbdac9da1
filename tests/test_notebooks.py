"""The notebooks in notebooks/ are executed documentation: they run top to bottom."""

import json
import pathlib

import pytest

NOTEBOOKS = sorted((pathlib.Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
NAMES = [p.name for p in NOTEBOOKS]


def test_notebooks_present():
    assert {"01_quickstart.ipynb", "02_reproduce_paper.ipynb", "03_find_missing_effect.ipynb",
            "04_uncertainty.ipynb", "05_sweep.ipynb"} <= set(NAMES)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=NAMES)
def test_stored_without_outputs_and_x64_first(path):
    nb = json.loads(path.read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert code, path.name
    for c in code:
        assert c.get("outputs") == [] and c.get("execution_count") is None, path.name
    first = "".join(code[0]["source"])
    assert "enable_x64()" in first, "the first code cell must call blurtrap.enable_x64()"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=NAMES)
def test_notebook_runs(path, tmp_path):
    try:
        import nbclient
        import nbformat
    except ImportError as exc:  # pragma: no cover - nbmake/nbclient not installed
        pytest.skip(f"nbclient/nbformat not importable ({exc}); install the test extras")
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=240, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors
