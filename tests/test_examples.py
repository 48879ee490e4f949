"""The notebooks in examples/: stored without outputs, and listed.

Each notebook asserts its key numbers against an independent value (the rod formula, the
controller law, the linear prediction, our own controller FMU, a two-DOF reference). They are
run top to bottom in a real Jupyter kernel (ipykernel) by the documentation build of
``tests/test_docs.py`` (myst-nb executes them afresh in a temporary folder and a failing cell
fails the build), which renders them with their outputs on the site.
"""

from __future__ import annotations

from pathlib import Path

from support.required import import_module

nbformat = import_module("nbformat")

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

