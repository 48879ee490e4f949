"""The notebooks in examples/ run top to bottom in a real Jupyter kernel (nbclient + ipykernel).

Each notebook asserts its key numbers against an independent value (the rod formula, the
controller law, the linear prediction, our own controller FMU, a two-DOF reference): a failing
cell fails the test with the cell's error. The notebooks are stored without outputs (checked
here too), and run in a temporary folder (what they write stays out of the checkout).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from support.required import import_module

nbformat = import_module("nbformat")
nbclient = import_module("nbclient")
import_module("ipykernel")

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "examples").glob("*.ipynb"))


def test_the_examples_are_there_and_stored_without_outputs() -> None:
    assert [p.stem for p in NOTEBOOKS] == ["01_quick_start", "02_delay_and_sampling",
                                           "03_your_own_controller", "04_stick_slip_top_drive"]
    for path in NOTEBOOKS:
        book = nbformat.read(path, as_version=4)
        nbformat.validate(book)
        for cell in book.cells:
            if cell.cell_type == "code":
                assert cell.outputs == [] and cell.execution_count is None, path.name


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_in_a_jupyter_kernel(path: Path, tmp_path: Path, project_fmus) -> None:
    book = nbformat.read(path, as_version=4)
    # kernel "python3" is ipykernel's: jupyter_client starts it with this interpreter (the
    # project's venv), so the notebook imports this drillcosim
    client = nbclient.NotebookClient(book, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    errors = [o for cell in book.cells if cell.cell_type == "code" for o in cell.outputs
              if o.output_type == "error"]
    assert not errors
