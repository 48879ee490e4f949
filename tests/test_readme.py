"""The generated FMU tables of the docs are current; the README gives the two commands."""

from __future__ import annotations

from pathlib import Path

import pytest

from drillcosim.fmu_src.interface_doc import END, START, interface_markdown

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def fmu_dir(project_fmus) -> Path:
    return project_fmus["DrillstringPlant"].parent


def test_docs_fmu_tables_match_the_built_fmus(fmu_dir):
    page = (ROOT / "docs" / "fmu_interface.md").read_text()
    block = page[page.index(START): page.index(END) + len(END)]
    assert block == interface_markdown(fmu_dir), \
        "regenerate: python -m drillcosim.fmu_src.interface_doc --write docs/fmu_interface.md"


def test_readme_quick_start_is_the_two_make_commands():
    readme = (ROOT / "README.md").read_text()
    assert "```\nmake run\nmake test\n```" in readme
    assert "make test" in (ROOT / ".ci" / "run").read_text()
