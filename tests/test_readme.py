"""The generated FMU tables of the docs are current; the README gives the two commands."""

from __future__ import annotations

from pathlib import Path

from drillcosim.fmu_src.interface_doc import END, START, interface_markdown

ROOT = Path(__file__).resolve().parents[1]


def test_docs_fmu_tables_are_the_port_tables():
    """The tables are generated from the port tables (the built FMUs are checked against those
    in tests/test_port_tables.py and tests/test_law_plugins.py)."""
    page = (ROOT / "docs" / "fmu_interface.md").read_text()
    block = page[page.index(START): page.index(END) + len(END)]
    assert block == interface_markdown(), \
        "regenerate: python -m drillcosim.fmu_src.interface_doc --write docs/fmu_interface.md"


def test_readme_quick_start_is_the_two_make_commands():
    readme = (ROOT / "README.md").read_text()
    assert "```\nmake run\nmake test\n```" in readme
    assert "make test" in (ROOT / ".ci" / "run").read_text()
