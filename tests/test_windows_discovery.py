"""Finding a Python on Windows, and the bad cases there: the win64 wrapper under wine.

A host without Python (``support/fmi2_probe.c`` built with mingw-w64: fmi2Instantiate and the FMI
logger's messages) loads the strain controller FMU's win64 DLL:

* the search order's Windows candidates: ``%DRILLCOSIM_PYTHON%``, ``PATH`` (``python.exe``),
  and the keys CPython's installer writes (PEP 514, ``HKEY_CURRENT_USER\\Software\\Python\\
  PythonCore\\3.X\\InstallPath``): the Python found there runs the FMU;
* a target Python that is too old (the official CPython 3.9 for Windows) or lacks numpy (the
  3.13 one without site-packages): fmi2Instantiate returns NULL after ONE fmi2Error message
  through the logger naming the candidate and what it lacks, never a crash or a hang; a 3.9
  registry key is not even tried (its tag is outside 3.10-3.13);
* a Python host that is too old (CPython 3.9 loading the DLL through ctypes): NULL and one
  message naming the version.

A 32-bit host cannot load the win64 DLL at all (tests/test_platforms.py reads its machine type:
x86-64): its loader refuses it with ERROR_BAD_EXE_FORMAT before any code of ours runs; the FMU
has no win32 binary, so a 32-bit FMI tool reports that the FMU does not support its platform.

Under CI a missing wine, mingw-w64 or Windows Python fails; elsewhere the tests skip.
"""

from __future__ import annotations

import dataclasses
import subprocess
import textwrap
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

from drillcosim.fmu_src.wrapper import HERE as WRAPPER_DIR
from support import windows_bench
from support.windows_bench import windows_path

pytestmark = [pytest.mark.needs_cc, pytest.mark.interop, pytest.mark.slow]

PROBE = Path(__file__).resolve().parent / "support" / "fmi2_probe.c"
CORE = "HKCU\\Software\\Python\\PythonCore"


@pytest.fixture(scope="module")
def bench(windows_caches: dict[str, str]) -> windows_bench.Bench:
    """The bench, its Windows processes on this run's shared caches (conftest)."""
    return dataclasses.replace(windows_bench.require(), base_env=windows_caches)


@pytest.fixture(scope="module")
def probe(bench, tmp_path_factory) -> Path:
    exe = tmp_path_factory.mktemp("probe") / "fmi2_probe.exe"
    subprocess.run([windows_bench.find_mingw(), "-std=c99", "-O1", "-Wall", "-Wextra",
                    "-Werror", f"-I{WRAPPER_DIR / 'fmi2'}", "-o", str(exe), str(PROBE)],
                   check=True, capture_output=True, text=True)
    return exe


@pytest.fixture(scope="module")
def controller(bench, project_fmus, tmp_path_factory) -> tuple[str, str, str]:
    """(DLL, resource URI, GUID) of the strain controller FMU unzipped, as Windows sees them."""
    folder = tmp_path_factory.mktemp("controller_unzipped")
    fmu = project_fmus["StrainController"]
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder)
    dll = folder / "binaries" / "win64" / "StrainController.dll"
    uri = "file:///" + windows_path(folder / "resources").replace("\\", "/")
    return windows_path(dll), uri, read_model_description(str(fmu)).guid


def instantiate(bench, probe, controller, **env: str) -> tuple[int, list[tuple[int, str]]]:
    """Run the probe under wine with no Python on PATH but what ``env`` names; (exit status,
    [(status, "category|message")])."""
    base = {"WINEPATH": "", "DRILLCOSIM_PYTHON": "", "XDG_CONFIG_HOME": "",
            "OPENBLAS_NUM_THREADS": "1"}
    proc = bench.run(probe, list(controller), env={**base, **env}, timeout=900)
    records = []
    for chunk in proc.stdout.split("\nEND\n"):
        head = chunk.split("LOG ", 1)
        if len(head) == 2:
            status, text = head[1].split(" ", 1)
            records.append((int(status), text))
    assert proc.stdout.rstrip().splitlines()[-1] in ("INSTANCE OK", "INSTANCE NULL"), (
        proc.stdout[-3000:])
    return proc.returncode, records


def _errors(records: list[tuple[int, str]]) -> list[str]:
    return [text for status, text in records if status >= 3]


def test_a_too_old_target_python_is_one_message_and_null(bench, probe, controller) -> None:
    old = windows_path(bench.root / "cp39" / "python.exe")
    rc, records = instantiate(bench, probe, controller, DRILLCOSIM_PYTHON=old)
    assert rc == 3
    errors = _errors(records)
    assert len(errors) == 1, records
    assert errors[0].startswith("logStatusError|probe: fmi2Instantiate: no usable Python found")
    assert f"1. $DRILLCOSIM_PYTHON = {old}: Python 3.9." in errors[0]
    assert "but the FMU runs on CPython 3.10 to 3.13 (an explicit choice" in errors[0]
    assert "How to fix: install numpy" in errors[0]


def test_a_target_python_without_numpy_is_one_message_and_null(bench, probe,
                                                                  controller) -> None:
    bare = windows_path(bench.root / "cp313-bare" / "python.exe")
    rc, records = instantiate(bench, probe, controller, DRILLCOSIM_PYTHON=bare)
    assert rc == 3
    errors = _errors(records)
    assert len(errors) == 1, records
    assert (f"1. $DRILLCOSIM_PYTHON = {bare}: Python 3.13.2, lacks numpy "
            f"(ModuleNotFoundError: No module named 'numpy')") in errors[0]
    assert "\\drillcosim\\drillcosim.conf" in errors[0]  # %APPDATA%'s, named in the fix


def test_python_exe_on_path_runs_the_fmu(bench, probe, controller) -> None:
    folder = windows_path(bench.root / "cp313")
    rc, records = instantiate(bench, probe, controller, WINEPATH=folder)
    assert rc == 0 and _errors(records) == [], records
    found = "\n".join(text for _s, text in records)
    assert f"3. on PATH: {folder}/python.exe: Python 3.13.2" in found, found
    assert "used" in found
    assert "4. the building interpreter" not in found  # found before: not reached


@pytest.fixture
def registered(bench):
    """PEP 514 keys as CPython's installer writes them (HKCU), removed afterwards: 3.13 (the
    one with the wheels), 3.9 (too old: not tried) and a 32-bit 3.12 (not tried)."""
    def reg(*args: str) -> None:
        proc = bench.run("reg", list(args), timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]

    py313, py39 = bench.root / "cp313", bench.root / "cp39"
    reg("add", f"{CORE}\\3.13\\InstallPath", "/ve", "/d", windows_path(py313) + "\\", "/f")
    reg("add", f"{CORE}\\3.13\\InstallPath", "/v", "ExecutablePath", "/d",
        windows_path(py313 / "python.exe"), "/f")
    reg("add", f"{CORE}\\3.13", "/v", "SysArchitecture", "/d", "64bit", "/f")
    reg("add", f"{CORE}\\3.9\\InstallPath", "/ve", "/d", windows_path(py39), "/f")
    reg("add", f"{CORE}\\3.12-32\\InstallPath", "/ve", "/d", windows_path(py39), "/f")
    try:
        yield windows_path(py313 / "python.exe")
    finally:
        bench.run("reg", ["delete", "HKCU\\Software\\Python", "/f"], timeout=300)


def test_the_registered_python_runs_the_fmu(bench, probe, controller, registered) -> None:
    rc, records = instantiate(bench, probe, controller)
    assert rc == 0 and _errors(records) == [], records
    found = "\n".join(text for _s, text in records)
    line = (f"3. registered (HKEY_CURRENT_USER\\Software\\Python\\PythonCore\\3.13): "
            f"{registered}: Python 3.13.2")
    assert line in found, found
    assert "3.9" not in found.split("3. registered", 1)[1].split("\n")[0]
    assert "PythonCore\\3.9" not in found and "3.12-32" not in found


OLD_HOST = textwrap.dedent("""
    import ctypes, sys
    lib = ctypes.CDLL(sys.argv[1])
    LOGGER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int,
                              ctypes.c_char_p, ctypes.c_char_p)
    messages = []
    def log(env, name, status, category, text):
        messages.append((status, category.decode() + "|" + text.decode()))
    class Callbacks(ctypes.Structure):
        _fields_ = [("logger", LOGGER), ("allocate", ctypes.c_void_p),
                    ("free", ctypes.c_void_p), ("step", ctypes.c_void_p),
                    ("env", ctypes.c_void_p)]
    keep = LOGGER(log)
    cb = Callbacks(keep, ctypes.cast(ctypes.cdll.msvcrt.calloc, ctypes.c_void_p),
                   ctypes.cast(ctypes.cdll.msvcrt.free, ctypes.c_void_p), None, None)
    lib.fmi2Instantiate.restype = ctypes.c_void_p
    lib.fmi2Instantiate.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                                    ctypes.c_char_p, ctypes.c_void_p, ctypes.c_int, ctypes.c_int]
    c = lib.fmi2Instantiate(b"old", 1, b"", sys.argv[2].encode(), ctypes.byref(cb), 0, 1)
    print(repr((c, sys.version.split()[0], messages)))
""")


def test_a_too_old_python_host_gets_one_message_and_null(bench, controller, tmp_path) -> None:
    script = tmp_path / "old_host.py"
    script.write_text(OLD_HOST)
    proc = bench.run_python(script, list(controller), python=bench.root / "cp39" / "python.exe",
                            timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    instance, version, messages = eval(proc.stdout.strip().splitlines()[-1])  # noqa: S307
    assert instance is None and version.startswith("3.9.")
    assert len(messages) == 1 and messages[0][0] == 3, messages
    text = messages[0][1]
    assert text.startswith(f"logStatusError|old: fmi2Instantiate: this process runs Python "
                           f"{version} "), text
    assert text.endswith("but the FMU's wrapper runs on CPython 3.10 to 3.13: load the FMU "
                         "from a process of one of these versions"), text
