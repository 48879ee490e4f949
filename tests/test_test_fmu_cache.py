"""The tiny test FMUs' cache: a full key, validation before use, rebuild of a broken file."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from support.master_fmus import build as test_fmus

pytestmark = [pytest.mark.needs_cc]


def test_a_broken_cached_fmu_is_rebuilt_never_reused(tmp_path: Path, monkeypatch) -> None:
    """The fresh-machine failure left 3-file FMUs (no binaries/) in the cache; they were reused."""
    monkeypatch.setenv("DRILLCOSIM_TEST_FMU_DIR", str(tmp_path))
    script = test_fmus.HERE / "mt_gain.py"
    target = tmp_path / f"mt_gain-{test_fmus.cache_key(script)}.fmu"
    with zipfile.ZipFile(target, "w") as zf:  # what the broken build wrote: 3 files
        with zipfile.ZipFile(test_fmus.build_fmu("mt_gain", tmp_path / "good")) as good:
            for member in ("modelDescription.xml", "resources/slavemodule.txt"):
                zf.writestr(member, good.read(member))
        zf.writestr("resources/mt_gain.py", script.read_text())
    problems = test_fmus.problems(target)
    assert any("binaries/linux64/MtGain.so missing" in p for p in problems)
    rebuilt = test_fmus.build_fmu("mt_gain")
    assert rebuilt == target and test_fmus.problems(rebuilt) == []


def test_the_cache_key_covers_script_pythonfmu_wrapper_and_build(monkeypatch, tmp_path) -> None:
    script = test_fmus.HERE / "mt_gain.py"
    key = test_fmus.cache_key(script)
    assert test_fmus.cache_key(test_fmus.HERE / "mt_mass.py") != key
    sources = test_fmus._recipe(script).sources()
    wrapper_c = next(p for p in sources if p.name == "fmi2_functions.c")
    assert {"build.py", "dcs_wrapper.h", "fmi2Functions.h"} <= {p.name for p in sources}
    copy = tmp_path / wrapper_c.name  # an edit of a wrapper source changes the key
    copy.write_bytes(wrapper_c.read_bytes() + b"\n")
    monkeypatch.setattr(test_fmus.project_build.FmuRecipe, "sources",
                        lambda self: [copy if p == wrapper_c else p for p in sources])
    assert test_fmus.cache_key(script) != key
    monkeypatch.undo()
    monkeypatch.setattr(test_fmus.pythonfmu, "__version__", "0.0.0")
    assert test_fmus.cache_key(script) != key
