"""The documentation site builds with warnings as errors, and executes the example notebooks.

One Sphinx build (``docs/conf.py``; what ``make docs`` runs) into a temporary folder, nitpicky
(``-n``: every cross-reference must resolve), every warning an error (``-W``: a broken link, a
missing page, a docstring numpydoc cannot parse, a notebook cell that raises), the notebooks of
``examples/`` executed afresh (``force``: not the content-keyed cache, since a notebook's result
depends on the code too). This build is the suite's run of the notebooks: each one asserts its
key numbers against an independent value, and a failing cell fails the build.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from support.required import import_module

for _name in ("sphinx", "numpydoc", "myst_nb", "sphinxarg"):
    import_module(_name)

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted(p.stem for p in (ROOT / "examples").glob("*.ipynb"))


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("docs")
    env = {**os.environ, "DRILLCOSIM_DOCS_EXECUTE": "force"}
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-n", "-W", "--keep-going",
                           "-q", "-d", str(out / "doctrees"), str(ROOT / "docs"), str(out / "html")],
                          capture_output=True, text=True, env=env, cwd=ROOT)
    warnings = [line for line in proc.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert proc.returncode == 0 and not [w for w in warnings if "[IPKernelApp]" not in w], \
        "\n".join(warnings) or proc.stderr[-3000:]
    return out / "html"


@pytest.mark.slow
def test_every_page_of_the_docs_folder_is_on_the_site(site: Path) -> None:
    pages = {p.stem for p in (ROOT / "docs").glob("*.md")}
    assert {"index", "getting_started", "architecture", "api", "cli", "fmu_interface",
            "paper_comparison", "delay_study", "interop", "citing"} <= pages
    assert sorted(p for p in pages if not (site / f"{p}.html").is_file()) == []


@pytest.mark.slow
def test_the_notebooks_are_rendered_with_their_outputs(site: Path) -> None:
    for stem in NOTEBOOKS:
        html = (site / "_generated" / "examples" / f"{stem}.html").read_text()
        assert 'class="cell_output' in html, stem     # outputs of executed cells
    # the figures of the quick start's res.plot() and the stick-slip notebook's plot
    for stem in ("01_quick_start", "04_stick_slip_top_drive"):
        html = (site / "_generated" / "examples" / f"{stem}.html").read_text()
        assert re.search(r'<img [^>]*src="(data:image/png|[^"]*\.png")', html), stem


@pytest.mark.slow
def test_the_cli_and_api_references_list_every_command_and_function(site: Path) -> None:
    from drillcosim.api import __all__ as api_names
    from drillcosim.cosim.cli import _parser

    cli = (site / "cli.html").read_text()
    commands = next(a for a in _parser()._actions if a.dest == "command").choices
    assert len(commands) >= 10
    assert [c for c in commands if f'id="drillcosim-{c}"' not in cli] == []
    options = {o for sub in commands.values() for a in sub._actions if a.dest != "help"
               for o in a.option_strings}
    assert "--stop-time" in options and [o for o in options if o not in cli] == []
    api = (site / "api.html").read_text()
    assert [n for n in api_names if n not in api] == []
