"""The notebooks in notebooks/ are executed documentation: they run top to bottom and show
their figures."""

import json
import pathlib
import re

import pytest

NOTEBOOKS = sorted((pathlib.Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
NAMES = [p.name for p in NOTEBOOKS]
# the figure functions of blurtrap.plotting (imported as bp in the notebooks)
FIGURE_CALL = re.compile(r"\bbp\.(fig\w+|corner|residuals_before_after|naive_error_map|"
                         r"diagnose_ranking)\(")


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
    check_figures_shown(nb, path.name)


def check_figures_shown(nb, name):
    """Every cell that draws a figure shows it as an image, once; no figure appears as its bare
    repr ('<Figure size 640x460 with 1 Axes>', what a figure outside pyplot's inline backend
    shows)."""
    code = [c for c in nb.cells if c.cell_type == "code"]
    images = 0
    for i, c in enumerate(code):
        data = [o.get("data", {}) for o in c.get("outputs", [])]
        pngs = [d for d in data if "image/png" in d]
        images += len(pngs)
        bare = [d["text/plain"] for d in data if "image/png" not in d
                and str(d.get("text/plain", "")).startswith("<Figure size")]
        assert not bare, f"{name}, code cell {i}: a figure shown as text, not drawn: {bare}"
        if FIGURE_CALL.search(c.source):
            assert pngs, f"{name}, code cell {i} draws a figure but shows no image/png"
        # a cell that also returns its figure shows it twice (once from the inline backend)
        assert not [o for o in c.get("outputs", []) if o.get("output_type") == "execute_result"
                    and "image/png" in o.get("data", {})], \
            f"{name}, code cell {i}: assign the figure (fig = ...) instead of returning it"
    plots = any(FIGURE_CALL.search(c.source) or "plt." in c.source for c in code)
    if plots:
        assert images >= 1, f"{name} plots but its executed outputs hold no image/png"


def test_figure_check_catches_figures_that_are_not_drawn():
    """What a user saw before the figures went through pyplot: the figure's repr as text."""
    nbformat = pytest.importorskip("nbformat")
    v4 = nbformat.v4
    shown = v4.new_code_cell("fig = bp.fig6_psd(rec, result)", outputs=[v4.new_output(
        "display_data", data={"image/png": "iVBORw0KGgo=", "text/plain": "<Figure size 640x460>"})])
    check_figures_shown(v4.new_notebook(cells=[shown]), "ok.ipynb")
    bare = v4.new_code_cell("bp.fig6_psd(rec, result)", outputs=[v4.new_output(
        "execute_result", data={"text/plain": "<Figure size 640x460 with 1 Axes>"},
        execution_count=1)])
    with pytest.raises(AssertionError, match="shown as text"):
        check_figures_shown(v4.new_notebook(cells=[bare]), "bare.ipynb")
    silent = v4.new_code_cell("fig = bp.corner(samples)", outputs=[])
    with pytest.raises(AssertionError, match="no image/png"):
        check_figures_shown(v4.new_notebook(cells=[silent]), "silent.ipynb")
    twice = v4.new_code_cell("bp.corner(samples)", outputs=[
        v4.new_output("execute_result", data={"image/png": "iVBORw0KGgo="}, execution_count=1),
        v4.new_output("display_data", data={"image/png": "iVBORw0KGgo="})])
    with pytest.raises(AssertionError, match="instead of returning it"):
        check_figures_shown(v4.new_notebook(cells=[twice]), "twice.ipynb")
