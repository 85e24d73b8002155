"""The notebooks in examples/ run top to bottom on tiny budgets, and are saved without outputs.

Each notebook keeps its budgets in one code cell tagged "parameters" (full size, for its readers)
and its tiny budgets in its metadata (`metadata.motorlab.tiny`: NAME -> Python expression). The
test runs a copy with a cell of those tiny values right after the parameters cell, in a Jupyter
kernel (nbclient), in a temporary folder; any cell error fails it. `{shared}` in a tiny value is
the absolute path of ../shared/data (reference data the repo does not copy).
"""

from __future__ import annotations

import os
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"
NOTEBOOKS = sorted((ROOT / "examples").glob("*.ipynb"))
EXPECTED = {"robust_pendulum", "sar_synergies", "forward_model_mpc", "your_own_body"}
CELL_TIMEOUT = 900


def tiny_cell(nb: nbformat.NotebookNode) -> tuple[int, str]:
    """Where the parameters cell is, and the source of the cell that makes its budgets tiny."""
    index = next((i for i, c in enumerate(nb.cells) if "parameters" in c.get("metadata", {}).get("tags", [])), None)
    assert index is not None, "no code cell tagged 'parameters' (the budgets, at the top)"
    tiny = nb.metadata.get("motorlab", {}).get("tiny")
    assert tiny, "no metadata.motorlab.tiny: the budgets make test runs the notebook with"
    source = nb.cells[index].source
    for name in tiny:
        assert f"{name} =" in source, f"tiny budget {name} is not set in the parameters cell"
    lines = [f"{name} = {value.replace('{shared}', str(SHARED_DATA))}" for name, value in tiny.items()]
    return index, "# make test: tiny budgets\n" + "\n".join(lines)


def test_every_notebook_is_there():
    assert {p.stem for p in NOTEBOOKS} >= EXPECTED


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_saved_without_outputs(path):
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, (
                f"{path.name} holds outputs: run `.venv/bin/nbstripout {path.relative_to(ROOT)}`")
    assert "widgets" not in nb.metadata, f"{path.name} holds widget state: run nbstripout on it"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_on_tiny_budgets(path, tmp_path):
    nb = nbformat.read(path, as_version=4)
    index, source = tiny_cell(nb)
    nb.cells.insert(index + 1, nbformat.v4.new_code_cell(source))
    os.environ.setdefault("MUJOCO_GL", "egl")  # the kernel inherits it
    client = NotebookClient(nb, timeout=CELL_TIMEOUT, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError, with the cell and its traceback, on any error
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert not [o for o in cell.outputs if o.get("output_type") == "error"]


def test_a_users_figures_still_show_after_motorlab_draws(tmp_path):
    """motorlab draws its figures to files; in Jupyter that must not switch the inline backend off."""
    nb = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell("import motorlab\n"
                                  "run = motorlab.train('InvertedPendulum-v5', 'ppo', 256, out='ppo', progress=False,\n"
                                  "                     hyperparams={'n_steps': 128, 'batch_size': 64})\n"
                                  "run.plot()"),
        nbformat.v4.new_code_cell("import matplotlib.pyplot as plt\nplt.plot([0, 1], [1, 0])\nplt.show()"),
    ])
    NotebookClient(nb, timeout=CELL_TIMEOUT, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
                   ).execute()
    assert (tmp_path / "ppo" / "plots" / "learning_curve.png").is_file()
    assert not any("image/png" in o.get("data", {}) for o in nb.cells[0].outputs)  # motorlab's own: files only
    assert any("image/png" in o.get("data", {}) for o in nb.cells[1].outputs)
