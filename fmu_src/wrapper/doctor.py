"""``drillcosim doctor [FMU]``: which Python an FMU of ours would run in on this machine, and why.

It lists the platforms the FMU carries a binary for (``binaries/linux64``, ``binaries/win64``);
on this machine's platform it runs the search below, for the others it says what they need.

The search is not re-implemented here: the FMU's own binary exports ``drillcosim_doctor``
(``dcs_python.c``), which runs the wrapper's discovery (``dcs_discover.c``: every candidate
checked in a child process, nothing loaded or started) for the unzipped FMU and returns the
report a C host would log at ``fmi2Instantiate``. This module unzips the FMU, calls it through
ctypes and adds what holds for Python hosts (fmpy, libcosimpy): the FMU runs in the host's own
interpreter, any CPython of the FMU's range with the required modules, and whether this Python
is one.

Exit status of the command: 0 when a host without Python would find a usable Python on this
machine, 1 when not (the report says what to install); a file that is not an FMU of ours is bad
input (one line, exit 2).
"""

from __future__ import annotations

import ctypes
import importlib.util
import json
import sys
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET

from drillcosim.fmu_src.platforms import PLATFORMS, host_platform

__all__ = ["Diagnosis", "NotAnFmuError", "PlatformReport", "diagnose", "doctor_command"]

REPORT_BYTES = 1 << 20  #: room for the C report (a few KB in practice)


class NotAnFmuError(ValueError):
    """The file named is not an FMU of ours (missing, not a zip, no binary, no doctor entry):
    bad input, one line."""


#: What a binary of each platform needs on a machine other than this one (the search order of
#: ``dcs_discover.c`` there; the doctor run on that machine names the Python it finds).
NEEDS = {
    "linux64": ("a 64-bit CPython {cpython} with a shared libpython and {needs}: the host's own "
                "interpreter in a Python host; else the first that fits of $DRILLCOSIM_PYTHON, "
                "'python = ...' in the FMU's drillcosim.conf or ~/.config/drillcosim/"
                "drillcosim.conf, python3 / python3.X on PATH"),
    "win64": ("a 64-bit CPython {cpython} for Windows with {needs}: the host's own interpreter "
              "in a Python host; else (Simulink, Dymola, OpenModelica, ...) the first that fits "
              "of %DRILLCOSIM_PYTHON%, 'python = C:\\...\\python.exe' in the FMU's "
              "drillcosim.conf or %APPDATA%\\drillcosim\\drillcosim.conf, python.exe / "
              "python3.exe / python3.X.exe on PATH, the Pythons python.org's installer "
              "registered (HKEY_CURRENT_USER or HKEY_LOCAL_MACHINE\\Software\\Python\\"
              "PythonCore\\3.X)"),
}


@dataclass(frozen=True)
class PlatformReport:
    """One platform an FMU carries a binary for.

    Attributes
    ----------
    platform : str
        ``linux64``, ``win64`` (FMI 2.0 names).
    binary : str
        Its member, ``binaries/<platform>/<model identifier><suffix>``.
    here : bool
        This machine's platform: the search of :attr:`Diagnosis.c_host_report` is its.
    uses : str
        What the binary will use: on this machine the Python found (or that none is), on
        another what it needs there.
    """

    platform: str
    binary: str
    here: bool
    uses: str


@dataclass(frozen=True)
class Diagnosis:
    """The doctor's findings for one FMU.

    Attributes
    ----------
    usable : bool
        A host without Python on this machine would find a Python that runs the FMU.
    c_host_report : str
        The wrapper's discovery report (each candidate, what it lacked, which would be used,
        and how to fix a failure), exactly as ``fmi2Instantiate`` words it.
    cpython : str
        The CPython versions the FMU runs in, e.g. ``"3.10-3.13"``.
    requires : tuple of str
        Modules a Python must import to run the FMU.
    this_python : str
        Whether the Python running the doctor could host the FMU (one line).
    platforms : tuple of PlatformReport
        The binaries the FMU carries, this machine's first.
    runtimes : dict of str -> dict of str -> str
        The Python runtimes a self-contained FMU carries, by platform (its MANIFEST's items:
        ``python``, ``files``, ``bytes``, ...); empty for a regular FMU.
    """

    usable: bool
    c_host_report: str
    cpython: str
    requires: tuple[str, ...]
    this_python: str
    platforms: tuple[PlatformReport, ...] = ()
    runtimes: dict[str, dict[str, str]] = field(default_factory=dict)

    def platform_lines(self) -> list[str]:
        """The platforms the FMU carries and, per platform, what it will use."""
        lines = ["Platforms: " + ", ".join(p.platform for p in self.platforms)
                 + " (none for 32-bit hosts: a 32-bit FMI tool cannot load this FMU)"]
        for p in self.platforms:
            where = " (this machine)" if p.here else ""
            lines.append(f"  {p.platform}{where}, {p.binary}: {p.uses}")
        return lines

    def self_contained_lines(self) -> list[str]:
        """Whether the FMU carries its own Python, and which one per platform."""
        if not self.runtimes:
            return ["Self-contained: no (it runs in a Python of the machine: see below; "
                    "`drillcosim build --standalone` writes self-contained FMUs)."]
        lines = ["Self-contained: yes: in a host without Python it runs in its own Python, "
                 "per platform:"]
        for platform, info in sorted(self.runtimes.items()):
            lines.append(f"  {platform}: CPython {info.get('python', '?')}, "
                         f"{info.get('files', '?')} files, "
                         f"{int(info.get('bytes', 0)) / 1e6:.0f} MB unpacked "
                         f"(resources/dcs_runtime/{platform})")
        return lines

    def text(self, fmu: Path) -> str:
        """The report printed by ``drillcosim doctor``."""
        verdict = ("a Python is found: the FMU runs here" if self.usable
                   else "no usable Python: the FMU does not run in a host without Python")
        needs = " ".join(self.requires) or "nothing"
        return "\n".join([
            f"FMU {fmu}",
            *self.platform_lines(),
            f"Verdict: {verdict}.",
            *self.self_contained_lines(),
            "",
            "In a host without Python of its own (a C/C++ FMI tool, fmusim, ...):",
            self.c_host_report.rstrip(),
            "",
            "In a Python host (fmpy, libcosimpy, ...): the FMU runs in the host's own interpreter"
            + (" (its own runtime is not loaded there: one process runs one Python)"
               if self.runtimes else "") + ",",
            f"which must be CPython {self.cpython} with these modules importable: {needs};",
            "a host of another version gets one message at fmi2Instantiate.",
            self.this_python,
        ]) + "\n"


def _model_identifier(fmu: Path, zf: zipfile.ZipFile) -> str:
    try:
        root = ET.fromstring(zf.read("modelDescription.xml"))
    except (KeyError, ET.ParseError) as exc:
        raise NotAnFmuError(f"{fmu}: not an FMU (no readable modelDescription.xml: {exc})") from None
    cs = root.find("CoSimulation")
    if cs is None or not cs.get("modelIdentifier"):
        raise NotAnFmuError(f"{fmu}: not a co-simulation FMU (no CoSimulation modelIdentifier)")
    return cs.get("modelIdentifier", "")


def _this_python(cpython: str, requires: tuple[str, ...]) -> str:
    low, high = (int(v.split(".")[1]) for v in cpython.split("-"))
    version = sys.version.split()[0]
    where = f"This Python ({version}, {sys.executable})"
    if sys.implementation.name != "cpython" or not low <= sys.version_info.minor <= high:
        return f"{where} cannot host it: not CPython {cpython}."
    missing = [m for m in requires if importlib.util.find_spec(m) is None]
    if missing:
        return (f"{where} cannot host it: it lacks {', '.join(missing)} "
                f"({sys.executable} -m pip install {' '.join(missing)}).")
    return f"{where} can host it."


def diagnose(fmu: Path | str) -> Diagnosis:
    """Run the FMU's own Python discovery on this machine without starting anything.

    Parameters
    ----------
    fmu : path-like
        An FMU built by drillcosim's build (its binary carries our wrapper).

    Returns
    -------
    Diagnosis

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not an FMU, not one of this platform, or not one whose binary is our wrapper.
    """
    fmu = Path(fmu)
    if not fmu.is_file():
        raise NotAnFmuError(f"{fmu}: no such FMU file")
    try:
        zf = zipfile.ZipFile(fmu)
    except zipfile.BadZipFile:
        raise NotAnFmuError(f"{fmu}: not an FMU (not a zip file)") from None
    with zf, tempfile.TemporaryDirectory(prefix="dcs_doctor_") as tmp:
        ident = _model_identifier(fmu, zf)
        here = host_platform()
        carried = [p for p in PLATFORMS.values() if p.library_name(ident) in zf.namelist()]
        if here is None or here not in {p.name for p in carried}:
            machine = here or "a platform the build does not know"
            has = ", ".join(p.name for p in carried) or "none"
            raise NotAnFmuError(f"{fmu}: no binary for this machine ({machine}); it carries "
                                f"{has}")
        binary = PLATFORMS[here].library_name(ident)
        zf.extractall(tmp)
        try:
            cpython = json.loads(zf.read("resources/dcs_build.json"))["cpython"]
        except (KeyError, ValueError):
            cpython = "3.10-3.13"  # an earlier build: its own report states its range
        lib = ctypes.CDLL(str(Path(tmp) / binary))
        entry = getattr(lib, "drillcosim_doctor", None)
        if entry is None:
            raise NotAnFmuError(f"{fmu}: its binary has no drillcosim_doctor: not an FMU built by "
                             "drillcosim's build (or built before the doctor existed)")
        entry.restype = ctypes.c_int
        entry.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_size_t]
        buf = ctypes.create_string_buffer(REPORT_BYTES)
        rc = entry(str(Path(tmp)).encode(), buf, REPORT_BYTES)
        requires_file = Path(tmp) / "resources" / "python_requires.txt"
        requires = tuple(requires_file.read_text().split()) if requires_file.is_file() else ()
    if rc < 0:
        raise RuntimeError(f"drillcosim_doctor refused its arguments (returned {rc})")
    # the FMU's own unzip folder is a temporary one here: name it as a host would have it
    report = buf.value.decode("utf-8", "replace").replace(tmp, "<the FMU's unzip folder>")
    from drillcosim.fmu_src.standalone import RUNTIME_DIR, runtimes

    carried_runtimes = runtimes(fmu)
    needs = " ".join(requires) or "nothing else"

    def uses(platform: str) -> str:
        if platform == here:
            return _verdict(rc == 1, report)
        if platform in carried_runtimes:
            return (f"in a host without Python its own CPython "
                    f"{carried_runtimes[platform].get('python', '?')} "
                    f"({RUNTIME_DIR}/{platform}); in a Python host that host's")
        return NEEDS.get(platform, "a 64-bit CPython {cpython}").format(cpython=cpython,
                                                                        needs=needs)

    reports = tuple(PlatformReport(p.name, p.library_name(ident), p.name == here, uses(p.name))
                    for p in sorted(carried, key=lambda p: p.name != here))
    return Diagnosis(usable=rc == 1, c_host_report=report, cpython=cpython, requires=requires,
                     this_python=_this_python(cpython, requires), platforms=reports,
                     runtimes=carried_runtimes)


def _verdict(usable: bool, report: str) -> str:
    """One line: the Python a host without one would use here (from the search's report)."""
    used = [ln.strip() for ln in report.splitlines()
            if ln.strip().endswith(("would be used", ", used"))]
    if usable and used:
        return "in a host without Python: " + used[0].split(": ", 1)[-1]
    return "no usable Python for a host without one (see below)"


def doctor_command(fmu: Path | str | None) -> int:
    """``drillcosim doctor [FMU]``: print the report; 0 if usable, 1 if not.

    ``fmu`` defaults to the built ``DrillstringPlant.fmu`` (``drillcosim build``'s folder).
    """
    if fmu is None:
        from drillcosim.fmu_src.build import default_out

        fmu = default_out() / "DrillstringPlant.fmu"
        if not fmu.is_file():
            raise NotAnFmuError(f"{fmu} does not exist: build it with `drillcosim build`, "
                                    "or name an FMU: drillcosim doctor FMU")
    diagnosis = diagnose(fmu)
    sys.stdout.write(diagnosis.text(Path(fmu)))
    return 0 if diagnosis.usable else 1
