"""Required tools: a test that finds one missing fails under CI and skips elsewhere.

The tools and interpreters the suite needs beyond pyproject's Python packages are the rows of
``.ci/required-tools`` (the one list: ``.ci/run`` installs each row or fails). A test that finds
a tool missing calls :func:`missing` with the row's name; a test that needs a Python package of
the test extras imports it with :func:`import_module`. Under CI (``CI`` set to ``true``, ``1`` or
``yes``, as CI services set it) both are failures, since ``.ci/run`` installed everything; on a
developer's machine they skip with one line naming what is missing.
"""

from __future__ import annotations

import importlib
import os
import subprocess
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import NoReturn

import pytest

ROOT = Path(__file__).resolve().parents[2]
TOOLS_FILE = ROOT / ".ci" / "required-tools"


@dataclass(frozen=True)
class Tool:
    """One row of ``.ci/required-tools``: its name, the bash check, the bash install ("-": none)."""

    name: str
    check: str
    install: str


def read_tools(path: Path = TOOLS_FILE) -> dict[str, Tool]:
    """The rows of the tool list by name (the format is described at the top of the file)."""
    tools: dict[str, Tool] = {}
    for number, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = [f.strip() for f in line.split("::")]
        if len(fields) != 3 or not all(fields):
            raise ValueError(f"{path.name}:{number}: expected 'name :: check :: install', got {line!r}")
        if fields[0] in tools:
            raise ValueError(f"{path.name}:{number}: {fields[0]!r} listed twice")
        tools[fields[0]] = Tool(*fields)
    return tools


def under_ci() -> bool:
    """Is this run CI's (``CI=true``)? There a missing required tool is a failure."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def missing(name: str, detail: str = "") -> NoReturn:
    """A required tool (a row ``name`` of ``.ci/required-tools``) is missing: fail under CI, else
    skip with one line naming it and ``detail`` (what was looked for, the error seen)."""
    if name not in read_tools():
        raise ValueError(f"{name!r} is not a row of .ci/required-tools (add it there)")
    _absent(f"required tool {name} is missing{': ' + detail if detail else ''} "
            "(.ci/run installs .ci/required-tools)")


def import_module(name: str) -> ModuleType:
    """``import name`` of a package in pyproject's dependencies or test extras (``make`` installs
    them): when absent, fail under CI, else skip with one line (``pytest.importorskip``, strict
    under CI)."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        _absent(f"Python package {name} is missing ({exc}; pip install -e '.[test]' installs it)")


def check(tool: Tool) -> subprocess.CompletedProcess:
    """Run ``tool``'s check as ``.ci/run`` does (bash, ``$ROOT`` set)."""
    return subprocess.run(["bash", "-c", tool.check], capture_output=True, text=True,
                          env={**os.environ, "ROOT": str(ROOT)}, timeout=120)


def _absent(message: str) -> NoReturn:
    if under_ci():
        pytest.fail(f"CI: {message}", pytrace=False)
    pytest.skip(message)
