"""The per-user cache folder is decided by two copies of one rule: the host's
(:func:`drillcosim._toolchain.user_cache`: built FMUs, unpacked FMUs, test FMUs) and the FMUs'
own (:func:`fmu_src.slave_support.vendored.cache_root`: the stable package copies and their
numba caches). The FMU side cannot import ``drillcosim`` (an FMU ships only its vendored
packages), so both must stay equal: ``$DRILLCOSIM_CACHE``, else ``$XDG_CACHE_HOME/drillcosim``,
else ``~/.cache/drillcosim``."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from drillcosim._toolchain import user_cache

ROOT = Path(__file__).resolve().parents[1]


def _fmu_side():
    # by file: the package's __init__ imports the vendored pythonfmu, absent in a host
    spec = importlib.util.spec_from_file_location(
        "_dcs_test_vendored", ROOT / "fmu_src" / "slave_support" / "vendored.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.cache_root


@pytest.mark.parametrize("env", [
    {"DRILLCOSIM_CACHE": "/x/dcs", "XDG_CACHE_HOME": "/x/xdg", "HOME": "/x/home"},
    {"XDG_CACHE_HOME": "/x/xdg", "HOME": "/x/home"},
    {"HOME": "/x/home"},
    {"DRILLCOSIM_CACHE": "", "XDG_CACHE_HOME": "", "HOME": "/x/home"},
])
def test_host_and_fmu_agree_on_the_cache_folder(env: dict[str, str],
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    for key in ("DRILLCOSIM_CACHE", "XDG_CACHE_HOME", "HOME"):
        monkeypatch.delenv(key, raising=False)
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    expected = (Path(env["DRILLCOSIM_CACHE"]) if env.get("DRILLCOSIM_CACHE")
                else Path(env.get("XDG_CACHE_HOME") or "/x/home/.cache") / "drillcosim")
    assert user_cache() == _fmu_side()() == expected
