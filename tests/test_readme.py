"""The README's generated parts are current."""

from __future__ import annotations

from pathlib import Path

import pytest

from fmu_src.interface_doc import END, START, interface_markdown

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def fmu_dir(tmp_path_factory) -> Path:
    d = ROOT / "build" / "fmus"
    if all((d / n).exists() for n in ("DrillstringPlant.fmu", "StrainController.fmu")):
        return d
    from fmu_src.build import build_all

    out = tmp_path_factory.mktemp("fmus")
    build_all(out)
    return out


def test_readme_fmu_tables_match_the_built_fmus(fmu_dir):
    readme = (ROOT / "README.md").read_text()
    block = readme[readme.index(START): readme.index(END) + len(END)]
    assert block == interface_markdown(fmu_dir), "regenerate: python -m fmu_src.interface_doc"


def test_readme_quick_start_is_the_two_make_commands():
    readme = (ROOT / "README.md").read_text()
    assert "```\nmake run\nmake test\n```" in readme
    assert "make test" in (ROOT / ".ci" / "run").read_text()
