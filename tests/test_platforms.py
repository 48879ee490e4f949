"""The platform matrix of the build: which binaries an FMU carries and how each is compiled.

* The choice of platforms (``--platforms linux64,win64``, default: every one whose compiler is
  found, a skipped one named in one line; a bad choice is bad input).
* The wrapper's C code compiles with gcc, clang and mingw-w64 with warnings as errors (the
  platform layer: one file per system behind ``dcs_platform.h``), for win64 against the headers
  of every CPython 3.10-3.13 on this machine with the Windows ``pyconfig.h``.
* What a binary is, read from its header and import table as a loader reads them: the win64
  DLL is x86-64 (a 32-bit host's loader refuses it: ERROR_BAD_EXE_FORMAT), exports the FMI
  functions and ``drillcosim_doctor``, and needs nothing but system DLLs (no python3X.dll: the
  C-API is looked up at run time; no libgcc/winpthread DLL); the linux64 library is ELF64
  x86-64 and needs no libpython.

Under CI (``CI=true``) a missing mingw-w64 or clang is a failure, elsewhere a skip naming it.
"""

from __future__ import annotations

import glob
import os
import shutil
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from drillcosim.fmu_src.build_c import MODEL_IDENTIFIER
from drillcosim.fmu_src.platforms import PLATFORMS, host_platform, select
from drillcosim.fmu_src.wrapper import compile_wrapper, python_range

pytestmark = [pytest.mark.needs_cc]

LOW, HIGH = python_range()


def _require(tool: str, hint: str) -> str:
    path = shutil.which(tool)
    if path is None:
        text = f"{tool} not found ({hint})"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(text + " (required under CI: .ci/run installs it)", pytrace=False)
        pytest.skip(text)
    return path


def mingw() -> str:
    return _require(PLATFORMS["win64"].cc, "Debian: apt install gcc-mingw-w64-x86-64")


def test_default_selection_names_what_it_skips(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DRILLCOSIM_CC_WIN64", "no-such-mingw-dcs")
    chosen = select()
    assert chosen.names == ("linux64",)
    assert chosen.note() == ("note: FMU binaries not built for win64: no-such-mingw-dcs not "
                             "found (Debian: apt install gcc-mingw-w64-x86-64; or set "
                             "$DRILLCOSIM_CC_WIN64)")
    monkeypatch.delenv("DRILLCOSIM_CC_WIN64")
    if shutil.which(PLATFORMS["win64"].cc):
        assert select().names == ("linux64", "win64") and select().note() == ""


def test_explicit_selection_is_checked(monkeypatch: pytest.MonkeyPatch) -> None:
    assert select("linux64").names == ("linux64",)
    assert select(["linux64", "linux64"]).names == ("linux64",)
    with pytest.raises(ValueError, match=r"win32 unknown; allowed: linux64, win64"):
        select("linux64,win32")
    with pytest.raises(ValueError, match="unknown"):
        select("")
    monkeypatch.setenv("DRILLCOSIM_CC_WIN64", "no-such-mingw-dcs")
    with pytest.raises(ValueError, match="cannot build for win64: no-such-mingw-dcs not found"):
        select("win64")


def test_the_native_platform_must_have_its_compiler(monkeypatch: pytest.MonkeyPatch) -> None:
    assert host_platform() == "linux64"
    monkeypatch.setenv("CC", "no-such-cc-dcs")
    with pytest.raises(ValueError, match=r"linux64 \(this machine\): no-such-cc-dcs not found"):
        select()


def test_cli_platforms_bad_input_is_one_line(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "drillcosim", "build", "--out", str(tmp_path),
                           "--platforms", "linux64,win32"], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "Traceback" not in proc.stderr
    assert "--platforms" in proc.stderr and "win32" in proc.stderr and "linux64, win64" in proc.stderr
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
def test_build_writes_the_chosen_platforms_and_names_a_skipped_one(tmp_path: Path) -> None:
    env = {**os.environ, "DRILLCOSIM_CC_WIN64": "no-such-mingw-dcs"}
    proc = subprocess.run([sys.executable, "-m", "drillcosim.fmu_src.build", "--out",
                           str(tmp_path), "--only", "StrainController"], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    notes = [ln for ln in proc.stdout.splitlines() if ln.startswith("note:")]
    assert notes == ["note: FMU binaries not built for win64: no-such-mingw-dcs not found "
                     "(Debian: apt install gcc-mingw-w64-x86-64; or set $DRILLCOSIM_CC_WIN64)"]
    with zipfile.ZipFile(tmp_path / "StrainController.fmu") as zf:
        assert [n for n in zf.namelist() if n.startswith("binaries/")] == [
            "binaries/linux64/StrainController.so"]


def test_the_wrapper_compiles_with_gcc_clang_and_mingw(tmp_path: Path) -> None:
    """-Wall -Wextra -Werror (a warning fails: compile_shared refuses any compiler output)."""
    assert compile_wrapper(tmp_path / "gcc.so", cc="gcc").stat().st_size > 0
    clang = _require("clang", "Debian: apt install clang")
    assert compile_wrapper(tmp_path / "clang.so", cc=clang).stat().st_size > 0
    mingw()
    assert compile_wrapper(tmp_path / "w.dll", platform="win64").stat().st_size > 0
    # the C controller: every build compiles it for both (the c_controller_fmu fixture)


def _pythons_with_headers() -> dict[int, str]:
    found = {}
    for minor in range(LOW, HIGH + 1):
        for inc in sorted(glob.glob(os.path.expanduser(
                f"~/.pyenv/versions/3.{minor}.*/include/python3.{minor}"))):
            if (Path(inc) / "Python.h").is_file():
                found[minor] = inc
    return found


def test_win64_wrapper_compiles_against_each_versions_headers(tmp_path: Path) -> None:
    """The limited API of 3.10 declared by a building CPython 3.10 and 3.13 (the oldest and the
    newest: 3.11 changed how pyport.h reads pyconfig.h; this interpreter's is the build's own),
    with the Windows pyconfig.h in place of its own."""
    mingw()
    from drillcosim.fmu_src.wrapper import HERE

    found = _pythons_with_headers()
    headers = {m: found[m] for m in {min(found, default=0), max(found, default=0)} if m in found}
    if not headers:
        pytest.skip("no CPython 3.10-3.13 headers under ~/.pyenv/versions")
    for minor, inc in headers.items():
        copy = tmp_path / f"inc3{minor}"
        shutil.copytree(inc, copy)
        shutil.copyfile(HERE / "win64" / "pyconfig.h", copy / "pyconfig.h")
        compile_wrapper(tmp_path / f"w3{minor}.dll", include=copy, platform="win64")


# ------------------------------------------------------------------ what the binaries are
def _pe(path: Path) -> tuple[int, set[str], set[str]]:
    """(machine, imported DLL names, exported names) of a PE file, read as the loader does."""
    data = path.read_bytes()
    pe = struct.unpack_from("<I", data, 0x3C)[0]
    assert data[pe:pe + 4] == b"PE\0\0"
    machine, n_sections, _, _, _, opt_size, _ = struct.unpack_from("<HHIIIHH", data, pe + 4)
    opt = pe + 24
    assert struct.unpack_from("<H", data, opt)[0] == 0x20B  # PE32+ (64-bit)
    dirs = opt + 112
    export_rva, _ = struct.unpack_from("<II", data, dirs)
    import_rva, _ = struct.unpack_from("<II", data, dirs + 8)
    sections = [struct.unpack_from("<8sIIII", data, opt + opt_size + 40 * i)
                for i in range(n_sections)]

    def offset(rva: int) -> int:
        for _name, vsize, vaddr, rawsize, rawptr in sections:
            if vaddr <= rva < vaddr + max(vsize, rawsize):
                return rva - vaddr + rawptr
        raise ValueError(rva)

    def cstr(rva: int) -> str:
        start = offset(rva)
        return data[start:data.index(b"\0", start)].decode()

    imports, pos = set(), offset(import_rva)
    while True:
        name_rva = struct.unpack_from("<IIIII", data, pos)[3]
        if name_rva == 0:
            break
        imports.add(cstr(name_rva).lower())
        pos += 20
    # export directory: NumberOfNames at +24, AddressOfNames at +32
    n_names = struct.unpack_from("<I", data, offset(export_rva) + 24)[0]
    names_rva = struct.unpack_from("<I", data, offset(export_rva) + 32)[0]
    exports = {cstr(struct.unpack_from("<I", data, offset(names_rva) + 4 * i)[0])
               for i in range(n_names)}
    return machine, imports, exports


def _elf_needed(path: Path) -> tuple[int, int, set[str]]:
    """(ELF class, machine, DT_NEEDED libraries) of a shared library, via readelf."""
    data = path.read_bytes()[:20]
    assert data[:4] == b"\x7fELF"
    machine = struct.unpack_from("<H", data, 18)[0]
    out = subprocess.run(["readelf", "-d", str(path)], capture_output=True, text=True).stdout
    needed = {line.split("[", 1)[1].split("]", 1)[0] for line in out.splitlines()
              if "(NEEDED)" in line}
    return data[4], machine, needed


def test_what_each_binary_needs(project_fmus: dict[str, Path], c_controller_fmu: Path,
                                tmp_path: Path) -> None:
    mingw()
    fmi = {"fmi2Instantiate", "fmi2DoStep", "fmi2GetReal", "fmi2SetReal", "fmi2FreeInstance",
           "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SerializeFMUstate"}
    system = {"kernel32.dll", "advapi32.dll", "msvcrt.dll"}
    for fmu in [*project_fmus.values(), c_controller_fmu]:
        with zipfile.ZipFile(fmu) as zf:
            names = [n for n in zf.namelist() if n.startswith("binaries/")]
            assert sorted(Path(n).parent.name for n in names) == ["linux64", "win64"], names
            for name in names:
                (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
                (tmp_path / name).write_bytes(zf.read(name))
                lib = tmp_path / name
                if name.endswith(".dll"):
                    machine, imports, exports = _pe(lib)
                    assert machine == 0x8664, hex(machine)  # x86-64: no 32-bit host loads it
                    assert imports <= system, imports  # no python3X.dll, no libgcc DLL
                    assert fmi <= exports, fmi - exports
                    if fmu != c_controller_fmu:
                        assert "drillcosim_doctor" in exports
                else:
                    elf_class, machine, needed = _elf_needed(lib)
                    assert (elf_class, machine) == (2, 62)  # ELFCLASS64, EM_X86_64
                    assert not any("python" in n for n in needed), needed
    assert MODEL_IDENTIFIER == c_controller_fmu.stem


def test_doctor_lists_the_platforms_and_what_each_uses(project_fmus: dict[str, Path],
                                                       tmp_path: Path) -> None:
    mingw()
    from drillcosim.fmu_src.wrapper.doctor import diagnose

    fmu = project_fmus["StrainController"]
    d = diagnose(fmu)
    assert [(p.platform, p.here, p.binary) for p in d.platforms] == [
        ("linux64", True, "binaries/linux64/StrainController.so"),
        ("win64", False, "binaries/win64/StrainController.dll")]
    assert d.platforms[0].uses == ("in a host without Python: " + next(
        ln.split(": ", 1)[1] for ln in d.c_host_report.splitlines()
        if ln.endswith("would be used")) if d.usable else
        "no usable Python for a host without one (see below)")
    assert d.platforms[1].uses.startswith("a 64-bit CPython 3.10-3.13 for Windows with numpy:")
    assert "%DRILLCOSIM_PYTHON%" in d.platforms[1].uses
    assert "Software\\Python\\PythonCore\\3.X" in d.platforms[1].uses
    lines = d.text(fmu).splitlines()
    assert lines[1] == ("Platforms: linux64, win64 (none for 32-bit hosts: a 32-bit FMI tool "
                        "cannot load this FMU)")
    # an FMU without this machine's binary: bad input, one line
    windows_only = tmp_path / "StrainController.fmu"
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(windows_only, "w") as dst:
        for info in src.infolist():
            if not info.filename.startswith("binaries/linux64/"):
                dst.writestr(info, src.read(info.filename))
    proc = subprocess.run([sys.executable, "-m", "drillcosim.cosim.cli", "doctor", str(windows_only)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0, proc.stderr
    assert "no binary for this machine (linux64); it carries win64" in proc.stderr
