"""Third-party FMI engines for the interop tests: libcosim (libcosimpy) and Ecos (ecospy).

Every engine runs in a subprocess with a timeout: the engines load the FMUs in process, and a
crash or a hang there must not take pytest down.

* :func:`run_libcosim` - ``CosimExecution.from_ssp_file`` (libcosim's fixed-step algorithm:
  Jacobi with a zero-order hold), the values after every step;
* :func:`run_ecos_cli` - the ``ecos`` command-line engine of the ecospy wheel
  (``ecos simulate --path X.ssp --stopTime S --stepSize H [--noParallel]``), its CSV;
* :func:`run_ecos_library` - the same engine through its C library ``libecosc`` (ecospy's
  ``EcosSimulation``, threaded stepping), the values after every step at full precision.

The Ecos CSV prints every Real with C++ ``std::to_string``, i.e. ``%f``: six decimals. A value
is therefore only known to +-5e-7 (absolute) from the CSV; :func:`compare` takes that
resolution into account, and the library run gives the full-precision comparison.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["CSV_RESOLUTION", "LIBCOSIM_HOST", "Comparison", "compare", "ecos_binary", "run_ecos_cli",
           "run_ecos_library", "run_libcosim"]

#: Half a unit of the sixth decimal: how far a value printed by Ecos's CSV (``%f``) may be
#: from the value the engine held.
CSV_RESOLUTION = 5e-7

#: A libcosimpy host script: ``python host.py SSP STEP_NS N_STEPS JSON_OUTPUTS`` prints
#: ``RESULT {"ok": ..., "rows": [...]}`` (the outputs after each step).
LIBCOSIM_HOST = textwrap.dedent("""
    import json, sys
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    ssp, step_ns, n_steps, wanted = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), \\
        json.loads(sys.argv[4])
    ex = CosimExecution.from_ssp_file(ssp, step_size=step_ns)
    obs = CosimObserver.create_last_value()
    ex.add_observer(observer=obs)
    index, refs = {}, {}
    for ref in wanted:
        inst = ref.split(".", 1)[0]
        if inst not in index:
            index[inst] = i = ex.slave_index_from_instance_name(inst)
            refs[inst] = {v.name.decode(): v.reference for v in ex.slave_variables(i)}
    cols = [(index[r.split(".")[0]], refs[r.split(".")[0]][r.split(".", 1)[1]]) for r in wanted]
    rows, ok = [], True
    for _ in range(n_steps):
        ok = ex.step(1) and ok
        rows.append([obs.last_real_values(i, [vr])[0] for i, vr in cols])
    print("RESULT " + json.dumps({"ok": bool(ok), "rows": rows}), flush=True)
    del obs
    del ex
""")

_ECOS_LIBRARY_HOST = textwrap.dedent("""
    import json, sys
    from ecospy import EcosSimulation

    ssp, step, n_steps, wanted, pset = (sys.argv[1], float(sys.argv[2]), int(sys.argv[3]),
                                        json.loads(sys.argv[4]), sys.argv[5])
    sim = EcosSimulation(ssp_path=ssp, step_size=step)
    ids = [w.replace(".", "::", 1) for w in wanted]
    ok = sim.init(parameter_set=pset)
    rows = [[sim.get_real(i) for i in ids]]
    for _ in range(n_steps):
        sim.step(1)
        rows.append([sim.get_real(i) for i in ids])
    sim.terminate()
    sim.free()
    print("RESULT " + json.dumps({"ok": bool(ok), "rows": rows}), flush=True)
""")


def _result(proc: subprocess.CompletedProcess, what: str) -> dict:
    if proc.returncode != 0:
        raise RuntimeError(f"{what} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if not lines:
        raise RuntimeError(f"{what} printed no result:\n{proc.stdout[-2000:]}"
                           f"{proc.stderr[-2000:]}")
    res = json.loads(lines[-1].removeprefix("RESULT "))
    if not res["ok"]:
        raise RuntimeError(f"{what}: a step failed:\n{proc.stderr[-3000:]}")
    return res


def run_libcosim(ssp: Path, step: float, n_steps: int, outputs: Sequence[str], workdir: Path,
                 timeout: float = 120.0) -> np.ndarray:
    """Values of ``outputs`` after each of ``n_steps`` libcosim steps, shape (n_steps, n_outputs).

    libcosim's step size is an integer number of nanoseconds: ``step`` must be one.
    """
    step_ns = round(step * 1e9)
    if abs(step_ns * 1e-9 - step) > 1e-15 * step:
        raise ValueError(f"libcosim steps in whole nanoseconds, got {step!r} s")
    host = workdir / "libcosim_host.py"
    host.write_text(LIBCOSIM_HOST)
    proc = subprocess.run([sys.executable, str(host), str(ssp), str(step_ns), str(n_steps),
                           json.dumps(list(outputs))], cwd=workdir, capture_output=True,
                          text=True, timeout=timeout)
    return np.array(_result(proc, "libcosim")["rows"], dtype=float)


def ecos_binary(workdir: Path) -> tuple[Path | None, str]:
    """An executable copy of ecospy's ``ecos`` engine, or (None, why it cannot run here).

    The wheel installs ``ecospy/binaries/ecos`` without the executable bit; the copy in
    ``workdir`` gets it (the installed package is left as it is).
    """
    spec = importlib.util.find_spec("ecospy")
    if spec is None or spec.origin is None:
        return None, "ecospy is not installed (pip install ecospy; it is in the test extras)"
    src = Path(spec.origin).parent / "binaries" / "ecos"
    if not src.is_file():
        return None, f"ecospy at {src.parent.parent} ships no Linux 'ecos' binary"
    exe = workdir / "ecos"
    if not exe.is_file():
        shutil.copy2(src, exe)
        exe.chmod(0o755)
    proc = subprocess.run([str(exe), "--version"], capture_output=True, text=True, timeout=60)
    if proc.returncode != 0:
        text = (proc.stderr or proc.stdout).strip()
        if "libtbb" in text:
            return None, ("Ecos needs Debian's libtbb12 (apt-get install libtbb12): "
                          f"{text.splitlines()[-1]}")
        return None, f"'ecos --version' failed: {text[-300:]}"
    return exe, proc.stdout.strip()


def _csv_config(outputs: Sequence[str]) -> str:
    by_inst: dict[str, list[str]] = {}
    for ref in outputs:
        inst, var = ref.split(".", 1)
        by_inst.setdefault(inst, []).append(var)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<ecos:CsvConfig xmlns:ecos="http://github.com/Ecos-platform/libecos/resources/'
             'schema/CsvConfig">', "  <ecos:components>"]
    for inst, names in by_inst.items():
        lines.append(f'    <ecos:component name="{inst}">')
        lines += [f'      <ecos:variable name="{n}"/>' for n in names]
        lines.append("    </ecos:component>")
    lines += ["  </ecos:components>", "</ecos:CsvConfig>", ""]
    return "\n".join(lines)


def run_ecos_cli(exe: Path, ssp: Path, step: float, stop: float, outputs: Sequence[str],
                 parameter_set: str, workdir: Path, parallel: bool,
                 timeout: float = 180.0) -> tuple[np.ndarray, dict[str, np.ndarray], str]:
    """Run ``ecos simulate`` on ``ssp`` and read its CSV (only ``outputs`` are logged).

    Returns
    -------
    (numpy.ndarray, dict, str)
        The times (one row per iteration, from 0), ``{'inst.var': values}`` and the CSV's text.
    """
    run_dir = workdir / ("ecos_threaded" if parallel else "ecos_serial")
    run_dir.mkdir(exist_ok=True)
    config = run_dir / "CsvConfig.xml"
    config.write_text(_csv_config(outputs))
    cmd = [str(exe), "simulate", "--path", str(ssp), "--stopTime", repr(stop), "--stepSize",
           repr(step), "--parameterSet", parameter_set, "--csvConfig", str(config),
           "-l", "warn", *([] if parallel else ["--noParallel"])]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONHOME", "PYTHONPATH")}
    proc = subprocess.run(cmd, cwd=run_dir, capture_output=True, text=True, timeout=timeout,
                          env=env)
    result = run_dir / f"{ssp.stem}.csv"
    if proc.returncode != 0 or not result.is_file():
        raise RuntimeError(f"{' '.join(cmd)} failed (exit {proc.returncode}):\n"
                           f"{proc.stdout[-2000:]}{proc.stderr[-3000:]}")
    text = result.read_text()
    rows = list(csv.reader(text.splitlines()))
    header = [h.strip() for h in rows[0]]
    body = np.array([[float(x) for x in r] for r in rows[1:]], dtype=float)
    cols = {}
    for j, h in enumerate(header[2:], start=2):
        inst, rest = h.split("::", 1)
        cols[f"{inst}.{rest.rsplit('[', 1)[0]}"] = body[:, j]
    missing = [o for o in outputs if o not in cols]
    if missing:
        raise RuntimeError(f"the Ecos CSV lacks {missing}; header: {header[:6]} ...")
    return body[:, 1], cols, text


def run_ecos_library(ssp: Path, step: float, n_steps: int, outputs: Sequence[str],
                     parameter_set: str, workdir: Path, timeout: float = 180.0) -> np.ndarray:
    """Values of ``outputs`` at 0 and after each step in Ecos's C library, shape (n_steps + 1, n)."""
    host = workdir / "ecos_library_host.py"
    host.write_text(_ECOS_LIBRARY_HOST)
    proc = subprocess.run([sys.executable, str(host), str(ssp), repr(step), str(n_steps),
                           json.dumps(list(outputs)), parameter_set], cwd=workdir,
                          capture_output=True, text=True, timeout=timeout)
    return np.array(_result(proc, "Ecos (libecosc)")["rows"], dtype=float)


@dataclass(frozen=True)
class Comparison:
    """Per signal: the largest difference to our master and the signal's peak.

    Attributes
    ----------
    diff : dict[str, float]
        max |engine - ours| over the run, in the signal's unit.
    peak : dict[str, float]
        max |ours|.
    """

    diff: dict[str, float]
    peak: dict[str, float]

    def relative(self) -> dict[str, float]:
        """diff / peak per signal (0 for a signal that stays 0 in both)."""
        return {k: (d / self.peak[k] if self.peak[k] > 0 else (0.0 if d == 0 else np.inf))
                for k, d in self.diff.items()}

    def worst(self, min_peak: float = 0.0) -> tuple[str, float]:
        """The signal with the largest relative difference (among peaks >= ``min_peak``)."""
        rel = {k: v for k, v in self.relative().items() if self.peak[k] >= min_peak}
        name = max(rel, key=rel.get)
        return name, rel[name]

    def summary(self, resolution: float = 0.0, rtol: float = 1e-9) -> str:
        """One line: the worst relative difference (of the signals ``resolution`` lets be
        resolved to ``rtol`` of their peak) and, with a resolution, the largest absolute
        difference of the other signals."""
        name, rel = self.worst(resolution / rtol)
        text = f"max difference to our master {rel:.3g} of the peak ({name})"
        if resolution:
            small = [k for k, p in self.peak.items() if p < resolution / rtol]
            far = max(small, key=self.diff.get)
            text += (f" over the {len(self.peak) - len(small)} signals with peak >= "
                     f"{resolution / rtol:g}; the {len(small)} others within "
                     f"{self.diff[far]:.3g} absolute ({far}; printing resolution {resolution:g})")
        return text

    def n_moving(self) -> int:
        """How many signals are not constant (the comparison is not between constants)."""
        return sum(p > 0 for p in self.peak.values())


def compare(ours: np.ndarray, theirs: dict[str, np.ndarray], rtol: float = 1e-9,
            resolution: float = 0.0) -> Comparison:
    """Compare an engine's signals with our master's, asserting ``rtol`` of each signal's peak.

    Parameters
    ----------
    ours : numpy.ndarray
        Our master's structured result (the same rows as ``theirs``).
    theirs : dict[str, numpy.ndarray]
        The engine's values per ``'inst.var'``.
    rtol : float
        Allowed difference as a fraction of the signal's peak.
    resolution : float
        Absolute resolution of the engine's numbers (:data:`CSV_RESOLUTION` for a CSV
        printed with ``%f``), added to the allowance.

    Raises
    ------
    AssertionError
        Naming the signal, the difference and the allowance.
    """
    diff, peak = {}, {}
    for name, values in theirs.items():
        mine = np.asarray(ours[name], dtype=float)
        if mine.shape != values.shape:
            raise AssertionError(f"{name}: {values.shape[0]} rows from the engine, "
                                 f"{mine.shape[0]} from our master")
        peak[name] = float(np.max(np.abs(mine)))
        d = np.abs(values - mine)
        diff[name] = float(np.max(d))
        allowed = rtol * peak[name] + resolution * (1 + 1e-9) + 4 * np.spacing(np.abs(mine))
        bad = np.flatnonzero(d > allowed)
        if bad.size:
            i = bad[0]
            raise AssertionError(f"{name}: row {i}: engine {values[i]!r}, ours {mine[i]!r}, "
                                 f"difference {d[i]:.3g} > {rtol:g} x peak {peak[name]:.4g}"
                                 f" + resolution {resolution:g}")
    return Comparison(diff, peak)
