"""What a researcher cites and installs: the license, the citation file, the version, the
changelog, one version number for all of them.

* ``CITATION.cff`` is valid Citation File Format 1.2.0 (``cffconvert --validate``, the format's
  own validator) and cites the paper the model comes from by its title and laboratory;
* the version of ``pyproject.toml`` (the one source) is the installed distribution's,
  ``drillcosim.__version__``, ``drillcosim --version``, the CITATION.cff version and the latest
  release of ``CHANGELOG.md``;
* ``LICENSE`` is the MIT license that ``pyproject.toml`` declares (SPDX ``MIT``).
"""

from __future__ import annotations

import re
import subprocess
import sys
from importlib.metadata import metadata
from pathlib import Path

import pytest

import drillcosim
from drillcosim.cosim.cli import main
from support.required import import_module

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
VERSION = PYPROJECT["project"]["version"]
PAPER = ("Three-dimensional multi-body bond graph model for vibration control of long shafts - "
         "application to oilwell drilling")


def test_citation_file_is_valid_cff() -> None:
    import_module("cffconvert")
    exe = Path(sys.executable).with_name("cffconvert")  # its console script (no __main__)
    proc = subprocess.run([str(exe), "--validate", "-i", str(ROOT / "CITATION.cff")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "valid according to schema version 1.2.0" in proc.stdout


def test_citation_file_cites_the_software_and_the_paper() -> None:
    yaml = import_module("ruamel.yaml")
    cff = yaml.YAML(typ="safe").load((ROOT / "CITATION.cff").read_text())
    assert cff["title"] == "drillcosim" and cff["version"] == VERSION
    assert cff["license"] == "MIT"
    (paper,) = cff["references"]
    assert " ".join(paper["title"].split()) == PAPER
    assert "Advanced Exploration Drilling Technology Laboratory" in paper["authors"][0]["name"]
    assert "Memorial University of Newfoundland" in paper["authors"][0]["name"]


def test_one_version_everywhere(capsys) -> None:
    assert metadata("drillcosim")["Version"] == VERSION
    assert drillcosim.__version__ == VERSION
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out == f"drillcosim {VERSION}\n"
    releases = re.findall(r"^## \[(\d+\.\d+\.\d+)\] - (\d{4}-\d{2}-\d{2})$",
                          (ROOT / "CHANGELOG.md").read_text(), flags=re.M)
    assert releases and releases[0][0] == VERSION, releases


def test_license_is_the_declared_mit() -> None:
    assert PYPROJECT["project"]["license"] == "MIT"
    assert PYPROJECT["project"]["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License\n") and "the drillcosim developers" in text
    assert "Permission is hereby granted, free of charge" in text
