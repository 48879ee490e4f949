"""Sphinx configuration of the drillcosim documentation (``make docs``: HTML into build/docs).

Sphinx with numpydoc and myst-nb, as numpy, scipy and python-control build theirs: the pages are
the Markdown files of this folder (MyST), the API reference comes from the numpydoc docstrings
(autodoc + autosummary), the CLI reference from the argparse parser (sphinx-argparse), the FMU
interface tables are generated into fmu_interface.md (``fmu_src/interface_doc.py``), and the notebooks of
``examples/`` are executed at build time and rendered with their outputs. ``make test`` builds
the site with warnings as errors (``tests/test_docs.py``).
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent

project = "drillcosim"
author = "The drillcosim authors"
copyright = "2026, the drillcosim authors"  # noqa: A001 (Sphinx's name)
try:
    from importlib.metadata import version as _version

    release = version = _version("drillcosim")
except Exception:  # pragma: no cover - an uninstalled checkout
    release = version = "unknown"

extensions = [
    "myst_nb",                       # Markdown pages (MyST) and executed notebooks
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx.ext.mathjax",
    "sphinxarg.ext",                 # the CLI reference from the argparse parser
]

exclude_patterns = ["_build", "**.ipynb_checkpoints"]
# .rst first: autosummary writes its generated pages (reStructuredText) with the first suffix
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
html_theme = "alabaster"
html_title = f"drillcosim {release}"
html_static_path: list[str] = []

# --- warnings are errors under `make test`: every reference must resolve
nitpicky = True
nitpick_ignore_regex = [
    # third-party and builtin types named in numpydoc type fields (no intersphinx: the build
    # must work offline)
    (r"py:.*", r"(numpy|np|pandas|pd|scipy|fmpy|matplotlib|dask|pathlib|collections|typing|os)\b.*"),
    (r"py:.*", r"(str|int|float|bool|dict|list|tuple|None|bytes|object|callable|mapping|sequence"
               r"|path-like|path|array-like|optional|default|iterable|DataFrame|ndarray|Path|Any"
               r"|Mapping|Sequence|Iterable|Callable|Literal)\b.*"),
    # the API's docstrings name the internal modules and functions they delegate to (relative
    # to the package: ``baseline.baseline_path``, :mod:`plots`); the reference documents the
    # public API only (no module pages), so those names are not links. A name of the public API
    # (drillcosim.api.*) must still resolve.
    (r"py:mod", r".*"),
    (r"py:.*", r"(?!drillcosim\.api\.)[a-z_]\w*\..*"),
    (r"py:.*", r"(summary|key_paths|plot_workers)"),
]
# myst.domains: sphinx-argparse's domain has no "any" resolver (MyST asks every domain)
suppress_warnings = ["myst.domains"]

# --- MyST: GitHub-style heading anchors, so links like page.md#section resolve
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath", "colon_fence"]

# --- numpydoc + autodoc
autosummary_generate = True
templates_path = ["_templates"]   # a class page documents its members in place
autodoc_typehints = "none"            # numpydoc's Parameters section carries the types
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# --- notebooks: executed at build time (cached by content: a notebook runs again only when it
# changed), in a temporary folder so what they write stays out of the checkout; a failing cell
# fails the build. DRILLCOSIM_DOCS_EXECUTE=off renders the notebooks unexecuted (quick edits).
nb_execution_mode = os.environ.get("DRILLCOSIM_DOCS_EXECUTE", "cache")
nb_execution_in_temp = True
nb_execution_raise_on_error = True
nb_execution_timeout = 900
nb_execution_cache_path = str(ROOT / "build" / "docs_cache" / "jupyter")


#: files at the top of the repository that have a page on the site: a link to one of them from a
#: docs page (``../BENCHMARKS.md``) or from an included file (``docs/performance.md``) works on
#: GitHub as written and is pointed at the page here
ROOT_PAGES = {"BENCHMARKS.md": "benchmarks.md", "CHANGELOG.md": "changelog.md",
              "CITATION.cff": "citing.md", "LICENSE": "license.md", "README.md": "index.md"}


def _relink(text: str, from_root: bool) -> str:
    """Links of a page (or, ``from_root``, of an included top-level file) as the site has them."""
    if from_root:
        text = re.sub(r"\]\(docs/", "](", text)
        text = re.sub(r"(!\[[^\]]*\]\()(?!https?:|/)([\w./-]+\))", r"\1../\2", text)
    for name, page in ROOT_PAGES.items():
        text = text.replace(f"](../{name})", f"]({page})")
        if from_root:
            text = text.replace(f"]({name})", f"]({page})")
    return text


def _source_read(app, docname: str, source: list[str]) -> None:
    source[0] = _relink(source[0], from_root=False)


def _include_read(app, relative_path, parent_docname: str, content: list[str]) -> None:
    if Path(relative_path).parent == Path(".."):   # a top-level file of the repository
        content[0] = _relink(content[0], from_root=True)


def _sync(src: Path, dst: Path) -> None:
    """Copy ``src`` to ``dst`` only when the content differs (Sphinx rereads on mtime)."""
    if not dst.exists() or dst.read_bytes() != src.read_bytes():
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst)


def setup(app) -> None:
    """The notebooks of examples/ are copied under _generated/ (a page must sit in this folder)."""
    for nb in sorted((ROOT / "examples").glob("*.ipynb")):
        _sync(nb, DOCS / "_generated" / "examples" / nb.name)
    app.connect("source-read", _source_read)
    app.connect("include-read", _include_read)
