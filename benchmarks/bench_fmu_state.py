"""FMU state calls: what the checks and the SHA-256 cost.

    python benchmarks/bench_fmu_state.py [--repeat 7] [--calls 200] [--baseline DIR]
        [--out benchmarks/results/fmu_state.md]

For the plant (paper_open_loop, full 3D, 30 bodies), the Python strain controller and the C
controller, in one process, this build and (``--baseline DIR``: e.g. main's ``build/fmus``)
an earlier one interleaved, best of ``--repeat`` x ``--calls``, us of CPU time (this thread's)
per call through fmpy's ``FMU2Slave`` (its ctypes wrapper costs the same for both builds):

* ``fmi2GetFMUstate`` (a state given back is overwritten: no allocation per call);
* ``fmi2SetFMUstate`` of that state (same parameters, same phase: the common restore);
* serialize: ``fmi2SerializedFMUstateSize`` + ``fmi2SerializeFMUstate`` of a fresh state (the
  payload encoded and sealed once per state; the size call makes it, the second copies it);
* deserialize: ``fmi2DeSerializeFMUstate`` of those bytes and ``fmi2FreeFMUstate`` (checks,
  SHA-256, payload decoded);
* the SHA-256 alone over the serialized size: the C implementation of the FMUs
  (``dcs_state_format.c``) and Python's hashlib.
"""

from __future__ import annotations

import argparse
import ctypes
import hashlib
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from drillcosim.fmu_src.wrapper import HERE, compile_shared  # noqa: E402

NAMES = ("DrillstringPlant", "StrainController", "StrainControllerC")


def _instance(folder: Path, name: str, tag: str) -> FMU2Slave:
    fmu = folder / f"{name}.fmu"
    md = read_model_description(str(fmu))
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)), modelIdentifier=name,
                  instanceName=f"{name}_{tag}")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    inputs = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    for k in range(10):
        s.setReal(inputs, [1e-6 if "Strain" in name else 100.0] * len(inputs))
        s.doStep(k * 1e-3, 1e-3)
    return s


def _per_call(fn, calls: int) -> float:
    """us of this thread's CPU time per call (steadier than wall time on a shared machine)."""
    t0 = time.thread_time()
    for _ in range(calls):
        fn()
    return (time.thread_time() - t0) / calls * 1e6


def _measure(s: FMU2Slave, calls: int) -> dict[str, float]:
    state = s.getFMUstate()
    blob = s.serializeFMUstate(state)

    def serialize() -> float:  # a fresh state each time: the payload is made once per state
        fresh = s.getFMUstate()
        t0 = time.thread_time()
        s.serializeFMUstate(fresh)  # fmpy: the size call, then the copy
        t1 = time.thread_time()
        s.freeFMUstate(fresh)
        return t1 - t0

    out = {"bytes": float(len(blob)),
           "get": _per_call(lambda: s.fmi2GetFMUstate(s.component, ctypes.byref(state)), calls),
           "set": _per_call(lambda: s.setFMUstate(state), calls),
           "serialize": sum(serialize() for _ in range(calls)) / calls * 1e6,
           "deserialize": _per_call(lambda: s.freeFMUstate(s.deSerializeFMUstate(blob)), calls)}
    s.freeFMUstate(state)
    return out


def _sha(lib, n: int, calls: int) -> tuple[float, float]:
    data = os.urandom(n)
    digest = ctypes.create_string_buffer(32)
    c = _per_call(lambda: lib.dcs_sha256(data, ctypes.c_size_t(n), digest), calls * 10)
    py = _per_call(lambda: hashlib.sha256(data).digest(), calls * 10)
    return c, py


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--baseline", type=Path, default=None)
    ap.add_argument("--fmus", type=Path, default=ROOT / "build" / "fmus")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "fmu_state.md")
    args = ap.parse_args(argv)
    builds = {"this build": args.fmus}
    if args.baseline is not None:
        builds["baseline"] = args.baseline
    inst = {(b, n): _instance(folder, n, b.replace(" ", "_")) for b, folder in builds.items()
            for n in NAMES}
    best: dict = {}
    for _ in range(args.repeat):
        for key, s in inst.items():  # interleaved
            for what, v in _measure(s, args.calls).items():
                best[key, what] = min(best.get((key, what), float("inf")), v)
    with tempfile.TemporaryDirectory() as tmp:
        lib = ctypes.CDLL(str(compile_shared(
            "the state format", [HERE / "dcs_state_format.c"], Path(tmp) / "fmt.so",
            flags=("-fvisibility=default", f"-I{HERE}"))))
        shas = {n: _sha(lib, int(best[("this build", n), "bytes"]), args.calls) for n in NAMES}
    lines = [
        "Command: `python benchmarks/bench_fmu_state.py "
        + " ".join(argv if argv is not None else sys.argv[1:]) + "`; "
        + time.strftime("%Y-%m-%d %H:%M") + f"; {platform.platform()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, load average {os.getloadavg()[0]:.1f} at the end; "
        f"best of {args.repeat} x {args.calls} calls, builds interleaved; us of CPU time (the "
        f"calling thread's) per call.", "",
        "| FMU | build | state bytes | get [us] | set [us] | serialize [us] | deserialize [us] "
        "| SHA-256 of it, C / hashlib [us] |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for n in NAMES:
        for b in builds:
            v = {w: best[(b, n), w] for w in ("bytes", "get", "set", "serialize", "deserialize")}
            sha = (f"{shas[n][0]:.1f} / {shas[n][1]:.1f}" if b == "this build" else "")
            lines.append(f"| {n} | {b} | {v['bytes']:.0f} | {v['get']:.1f} | {v['set']:.1f} | "
                         f"{v['serialize']:.1f} | {v['deserialize']:.1f} | {sha} |")
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)
    for s in inst.values():
        s.terminate()
        s.freeInstance()
    return 0


if __name__ == "__main__":
    sys.exit(main())
