"""The project's prose names no development machine: no absolute paths of a machine (its home,
temporary or work folders), no worktree or branch names of its development, no issue numbers a
reader cannot open.

Read: every markdown file, the notebooks' cells, the citation file, the scene files, and the
docstrings and comments of every Python file in the repository (git's list of files). A command
in the docs names folders by what they are (``BEFORE``, ``OUT``, a git worktree of a commit),
and a measurement says what was measured, not which issue asked for it.
"""

from __future__ import annotations

import io
import json
import re
import subprocess
import tokenize
from pathlib import Path

import pytest

from support.required import missing

ROOT = Path(__file__).resolve().parents[1]
#: what a development machine leaves behind: (name, pattern)
FORBIDDEN = (
    ("an absolute path of a machine",
     re.compile(r"(?<![\w.~])/(?:work|tmp|root|home|Users|mnt|srv)/[\w.<]|[A-Z]:\\\\Users")),
    ("a worktree or branch name", re.compile(r"\bwt-[a-z0-9]|\bi\d\d[a-z]\b")),
    ("an issue number", re.compile(r"\b[Ii]ssues? #?\d")),
    ("a reference to an issue", re.compile(r"\b[Tt]he issue(?:'s)?\b")),
)
#: the test files that must spell the patterns out
SELF = {"tests/test_no_machine_paths.py"}


def _files() -> list[str]:
    proc = subprocess.run(["git", "-C", str(ROOT), "ls-files"], capture_output=True, text=True)
    if proc.returncode != 0:
        missing("git-history", f"git ls-files failed: {proc.stderr.strip()}")
    return [f for f in proc.stdout.splitlines() if f not in SELF and (ROOT / f).is_file()]


def _python_prose(text: str) -> str:
    """The docstrings (every string that is a statement of its own) and comments of a module."""
    out, previous = [], tokenize.NEWLINE
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            out.append(tok.string)
        elif tok.type == tokenize.STRING and previous in (tokenize.NEWLINE, tokenize.INDENT,
                                                          tokenize.DEDENT, tokenize.NL):
            out.append(tok.string)
        if tok.type not in (tokenize.COMMENT, tokenize.NL):
            previous = tok.type
    return "\n".join(out)


def _prose(path: str) -> str | None:
    text = (ROOT / path).read_text(errors="replace")
    if path.endswith((".md", ".cff", ".toml")):
        return text
    if path.endswith(".ipynb"):
        return "\n".join("".join(c["source"]) for c in json.loads(text)["cells"])
    if path.endswith(".py"):
        return _python_prose(text)
    return None


def test_the_prose_names_no_development_machine() -> None:
    found = []
    files = _files()
    assert any(f.endswith(".md") for f in files) and any(f.endswith(".py") for f in files)
    for path in files:
        prose = _prose(path)
        if prose is None:
            continue
        for what, pattern in FORBIDDEN:
            for match in pattern.finditer(prose):
                line = prose[:match.start()].count("\n") + 1
                found.append(f"{path} (prose line {line}): {what}: "
                             f"{prose.splitlines()[line - 1].strip()[:120]!r}")
    assert found == [], "\n".join(found)


@pytest.mark.parametrize(("text", "what"), [
    ("see /work/checkout/build/fmus", "an absolute path of a machine"),
    ("python x.py --base-tree /tmp/plant_base", "an absolute path of a machine"),
    ("the worktree wt-before at ae51f5f", "a worktree or branch name"),
    ("merged branch i30a", "a worktree or branch name"),
    ("this page (issue 16) answers", "an issue number"),
    ("the issue's 3 % bar", "a reference to an issue"),
])
def test_the_patterns_catch_what_they_name(text: str, what: str) -> None:
    assert [name for name, pattern in FORBIDDEN if pattern.search(text)] == [what]


def test_docstrings_and_comments_are_what_is_read() -> None:
    source = 'x = "/tmp/a"  # issue 5\n\ndef f():\n    """A docstring: /work/x."""\n    return "wt-9"\n'
    prose = _python_prose(source)
    assert "# issue 5" in prose and "/work/x" in prose
    assert '"/tmp/a"' not in prose and "wt-9" not in prose
