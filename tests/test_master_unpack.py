"""Where the master unpacks FMUs (cosim.master.unpack): once per content, in the user cache."""

from __future__ import annotations

import os
import shutil
import sys
import time

import pytest

from drillcosim.cosim.master import unpack as unpack_module
from drillcosim.cosim.master.execution import Execution
from drillcosim.cosim.master.system import FmuSpec, SystemSpec
from drillcosim.cosim.master.unpack import unpack


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DRILLCOSIM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "unpacked"


def test_one_folder_per_content_reused_and_kept(fmus, cache, tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "dont_write_bytecode", False)   # as without PYTHONDONTWRITEBYTECODE
    first, owned = unpack(fmus["mt_integrator"])
    assert not owned and os.path.dirname(first) == str(cache)
    copy = tmp_path / "renamed.fmu"                     # same content, another name
    shutil.copy(fmus["mt_integrator"], copy)
    assert unpack(copy) == (first, False)
    other, _ = unpack(fmus["mt_gain"])
    assert other != first and len(os.listdir(cache)) == 2
    with open(os.path.join(first, "resources", "slavemodule.txt")) as fh:
        module = fh.read().strip()
    imported_before = module in sys.modules       # then the FMU's module is not imported again
    system = SystemSpec([FmuSpec("i", fmus["mt_integrator"], {"u": 1.0})], base_step=0.01)
    with Execution(system, read_outputs=["i.x"]) as ex:
        ex.simulate_until(0.5)
        assert ex.get_real("i.x") == pytest.approx(0.5)
    # the run left the folder (and the byte code of the FMU's Python sources) in place
    assert os.path.isfile(os.path.join(first, "modelDescription.xml"))
    if not imported_before:
        assert any("__pycache__" in dirs for _root, dirs, _files in os.walk(first))


def test_a_broken_cache_folder_or_an_unwritable_cache_falls_back(fmus, cache, monkeypatch):
    first, _ = unpack(fmus["mt_integrator"])
    os.remove(os.path.join(first, "modelDescription.xml"))       # damaged by hand
    folder, owned = unpack(fmus["mt_integrator"])
    assert owned and folder != first and os.path.isfile(os.path.join(folder,
                                                                     "modelDescription.xml"))
    shutil.rmtree(folder)
    monkeypatch.setenv("DRILLCOSIM_CACHE", "/proc/no-such-cache")
    folder, owned = unpack(fmus["mt_gain"])
    assert owned and os.path.isfile(os.path.join(folder, "modelDescription.xml"))
    shutil.rmtree(folder)


def test_old_folders_beyond_the_newest_are_pruned(fmus, cache, monkeypatch):
    monkeypatch.setattr(unpack_module, "KEEP", 1)
    old, _ = unpack(fmus["mt_integrator"])
    week_ago = time.time() - 8 * 24 * 3600
    os.utime(old, (week_ago, week_ago))
    new, _ = unpack(fmus["mt_gain"])
    assert os.path.isdir(new) and not os.path.exists(old)
