"""Self-contained FMUs: their size, and their first fmi2Instantiate next to a regular FMU's.

    python benchmarks/bench_standalone.py [--repeat 5]

1. Size of the self-contained plant and controller FMUs (``drillcosim build --standalone``)
   per platform (linux64; the plant's win64 runtime too, from the embeddable CPython and the
   wheels pip downloads, unless ``--no-win64``): the ``.fmu`` (compressed) and the runtime
   unpacked, and what dominates the plant's runtime (zip members grouped by component).
2. The first ``fmi2Instantiate`` in a fresh process of a plain C host (no Python in it) of the
   regular plant FMU (its Python found by the discovery: ``$DRILLCOSIM_PYTHON`` = this
   interpreter, checked in a child process, then started) and of the self-contained one (its
   own runtime: every file's size and SHA-256 checked, then started), interleaved, ``--repeat``
   times each after one warm-up of each (numba's cache and the native images warm, as after a
   first run on a machine), on the same machine in the same run; the wrapper's own log line
   of the self-contained start gives the CPU time of the check and of the interpreter start.
   With ``--wine`` the same under wine: the win64 binaries in the mingw-built C host, the
   regular FMU running in the Windows bench's CPython (``tests/support/windows_bench.py``).

The FMUs are built fresh into a temporary folder (the runtime comes from the per-user cache of
runtimes when it was assembled before). Prints a markdown section (for docs/performance.md).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drillcosim.fmu_src.build import REGISTRY, build_one  # noqa: E402
from drillcosim.fmu_src.standalone import RUNTIME_DIR, make_standalone  # noqa: E402
from drillcosim.fmu_src.wrapper import HERE as WRAPPER_DIR  # noqa: E402

TIMER = r"""
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "fmi2Functions.h"
static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c,
                   fmi2String m, ...) { va_list ap; (void)e; (void)n; (void)c;
    fprintf(stderr, "[%d] ", (int)s); va_start(ap, m); vfprintf(stderr, m, ap); va_end(ap);
    fputc('\n', stderr); }
int main(int argc, char **argv) {
    char lib[4096], uri[4200]; struct timespec a, b; void *h; fmi2Component c;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    snprintf(lib, sizeof lib, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    h = dlopen(lib, RTLD_NOW | RTLD_LOCAL);
    if (h == NULL || argc < 3) return 2;
    fmi2InstantiateTYPE *inst = (fmi2InstantiateTYPE *)dlsym(h, "fmi2Instantiate");
    fmi2FreeInstanceTYPE *fr = (fmi2FreeInstanceTYPE *)dlsym(h, "fmi2FreeInstance");
    clock_gettime(CLOCK_MONOTONIC, &a);
    c = inst("bench", fmi2CoSimulation, "", uri, &cb, fmi2False, fmi2True);
    clock_gettime(CLOCK_MONOTONIC, &b);
    printf("%.6f\n", (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec));
    if (c == NULL) return 3;
    fr(c);
    return 0;
}
"""

COMPONENTS = (("llvmlite (numba's LLVM)", r"site-packages/llvmlite"),
              ("numpy + numpy.libs (OpenBLAS)", r"site-packages/numpy"),
              ("scipy + scipy.libs (OpenBLAS)", r"site-packages/scipy"),
              ("numba", r"site-packages/numba"),
              ("libpython / python3XX.dll", r"(lib/libpython|/python3\d+\.dll)"),
              ("standard library (.pyc zip)", r"python3\d+\.zip"),
              ("extension modules (lib-dynload, .pyd)", r"(lib-dynload/|\.pyd$)"))


def sizes(fmu: Path) -> tuple[dict[str, list[int]], int, int]:
    """Per component [compressed, unpacked] bytes of the runtime, and its totals."""
    groups: dict[str, list[int]] = {name: [0, 0] for name, _ in COMPONENTS}
    groups["other"] = [0, 0]
    packed = unpacked = 0
    with zipfile.ZipFile(fmu) as zf:
        for info in zf.infolist():
            if not info.filename.startswith(RUNTIME_DIR + "/"):
                continue
            name = next((n for n, pat in COMPONENTS if re.search(pat, info.filename)), "other")
            groups[name][0] += info.compress_size
            groups[name][1] += info.file_size
            packed += info.compress_size
            unpacked += info.file_size
    return groups, packed, unpacked


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--no-win64", action="store_true", help="leave out the win64 runtime "
                        "(its embeddable CPython and wheels are downloaded with pip)")
    parser.add_argument("--wine", action="store_true", help="also compare the first "
                        "fmi2Instantiate under wine (needs the Windows bench of the tests)")
    args = parser.parse_args(argv)
    started = _dt.datetime.now()
    tmp = Path(tempfile.mkdtemp(prefix="bench_standalone_"))
    recipes = {r.name: r for r in REGISTRY}
    fmus = {}
    for name in ("DrillstringPlant", "StrainController"):
        regular = build_one(recipes[name], tmp / "regular")
        fmus[name] = (regular, make_standalone(regular, tmp / "standalone" / regular.name,
                                               ("linux64",)))
    out = ["## Self-contained FMUs: size and first fmi2Instantiate (benchmarks/bench_standalone.py)",
           "", f"`python benchmarks/bench_standalone.py --repeat {args.repeat}` on "
           f"{started:%Y-%m-%d %H:%M}, {platform.platform()}, {os.cpu_count()} CPUs, Python "
           f"{platform.python_version()}.", "",
           "| FMU | platform | regular .fmu | self-contained .fmu | runtime unpacked | files |",
           "|---|---|---:|---:|---:|---:|"]
    for name, (regular, standalone) in fmus.items():
        _groups, _packed, unpacked = sizes(standalone)
        with zipfile.ZipFile(standalone) as zf:
            n = sum(1 for i in zf.infolist() if i.filename.startswith(RUNTIME_DIR + "/"))
        if name == "DrillstringPlant":
            plant_unpacked = unpacked  # the runtime the Linux C host checks below
        out.append(f"| {name} | linux64 | {regular.stat().st_size / 1e6:.2f} MB | "
                   f"{standalone.stat().st_size / 1e6:.1f} MB | {unpacked / 1e6:.0f} MB | {n} |")
    plant = fmus["DrillstringPlant"][0]
    if not args.no_win64:  # the win64 runtime alone (the FMU's win64 binary is the wrapper's)
        win = make_standalone(plant, tmp / "win64" / plant.name, ("win64",))
        _groups, _packed, unpacked = sizes(win)
        with zipfile.ZipFile(win) as zf:
            n = sum(1 for i in zf.infolist() if i.filename.startswith(RUNTIME_DIR + "/"))
        out.append(f"| DrillstringPlant | win64 | {plant.stat().st_size / 1e6:.2f} MB | "
                   f"{win.stat().st_size / 1e6:.1f} MB | {unpacked / 1e6:.0f} MB | {n} |")
        both = make_standalone(plant, tmp / "both" / plant.name)  # every platform it carries
        _groups, _packed, unpacked = sizes(both)
        out.append(f"| DrillstringPlant | linux64 + win64 (`drillcosim build --standalone` of "
                   f"an FMU with both binaries) | {plant.stat().st_size / 1e6:.2f} MB | "
                   f"{both.stat().st_size / 1e6:.1f} MB | {unpacked / 1e6:.0f} MB | |")
    breakdown = [("linux64", fmus["DrillstringPlant"][1])]
    if not args.no_win64:
        breakdown.append(("win64", win))
    for name_platform, fmu in breakdown:
        groups, packed, unpacked = sizes(fmu)
        out += ["", f"What the plant's {name_platform} runtime is made of:", "",
                "| component | compressed | unpacked | share of compressed |",
                "|---|---:|---:|---:|"]
        for name, (c, u) in sorted(groups.items(), key=lambda kv: -kv[1][0]):
            out.append(f"| {name} | {c / 1e6:.1f} MB | {u / 1e6:.1f} MB | "
                       f"{100 * c / packed:.0f} % |")
        out.append(f"| total | {packed / 1e6:.1f} MB | {unpacked / 1e6:.1f} MB | 100 % |")

    # first fmi2Instantiate, fresh processes, interleaved
    (tmp / "timer.c").write_text(TIMER)
    timer = tmp / "timer"
    subprocess.run(["gcc", "-std=c99", "-O1", f"-I{WRAPPER_DIR / 'fmi2'}", "-o", str(timer),
                    str(tmp / "timer.c"), "-ldl"], check=True)
    unzipped = {}
    for kind, index in (("regular", 0), ("self-contained", 1)):
        folder = tmp / f"unzip-{kind}"
        with zipfile.ZipFile(fmus["DrillstringPlant"][index]) as zf:
            zf.extractall(folder)
        unzipped[kind] = folder
    empty = tmp / "empty"
    empty.mkdir()
    base = {k: v for k, v in os.environ.items()
            if not k.startswith(("PYTHON", "DRILLCOSIM_PYTHON", "VIRTUAL_ENV", "LD_LIBRARY"))}
    envs = {"regular": {**base, "DRILLCOSIM_PYTHON": sys.executable, "PATH": "/usr/bin:/bin"},
            "self-contained": {**base, "PATH": str(empty)}}
    times: dict[str, list[float]] = {k: [] for k in envs}
    check_cpu: list[float] = []
    start_cpu: list[float] = []
    for i in range(args.repeat + 1):
        for kind in envs:
            proc = subprocess.run([str(timer), str(unzipped[kind]), "DrillstringPlant"],
                                  env=envs[kind], capture_output=True, text=True, timeout=900)
            if proc.returncode != 0:
                raise RuntimeError(f"{kind}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
            if i == 0:
                continue  # warm-up: numba's cache and the native images of this machine
            times[kind].append(float(proc.stdout.split()[-1]))
            found = re.search(r"CPU time: ([\d.]+) s to check .*?, ([\d.]+) s to start",
                              proc.stderr)
            if found:
                check_cpu.append(float(found.group(1)))
                start_cpu.append(float(found.group(2)))
    med = {k: statistics.median(v) for k, v in times.items()}
    out += ["", f"First `fmi2Instantiate` of the plant in a fresh C-host process (median of "
            f"{args.repeat}, warm numba cache; wall time of the call):", "",
            "| FMU | fmi2Instantiate | min | max |", "|---|---:|---:|---:|"]
    for kind, values in times.items():
        out.append(f"| {kind} | {med[kind]:.3f} s | {min(values):.3f} s | "
                   f"{max(values):.3f} s |")
    out += ["", f"Self-contained / regular: {med['self-contained'] / med['regular']:.2f}x. Of "
            f"the self-contained start (CPU time, median): the runtime's check (every file's "
            f"size and SHA-256, {plant_unpacked / 1e6:.0f} MB) {statistics.median(check_cpu):.3f} s, "
            f"the interpreter's start {statistics.median(start_cpu):.3f} s; the rest is the "
            f"slave's import and the native images (as for the regular FMU). The regular FMU "
            f"checks its Python in a child process first (`python -E -X utf8 -c ...`: version, "
            f"libpython, `import numpy scipy numba`)."]
    if args.wine:
        out += wine_first_instantiate(fmus["DrillstringPlant"][0], tmp, args.repeat)
    print("\n".join(out))
    return 0


def wine_first_instantiate(plant: Path, tmp: Path, repeat: int) -> list[str]:
    """The same comparison under wine: the regular plant's win64 binary with the bench's
    Windows CPython named by ``DRILLCOSIM_PYTHON``, and the self-contained one with its win64
    runtime, in the plain C host built with mingw-w64 (its own timer: QueryPerformanceCounter)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from support import cosim_host, windows_bench

    bench = windows_bench.prepare(log=lambda *_: None)
    os.environ.setdefault("DRILLCOSIM_WIN64_DOWNLOADS", str(
        windows_bench.bench_dir() / "downloads" / "win_amd64-cp313"))
    standalone = make_standalone(plant, tmp / "wine" / plant.name, ("win64",))
    exe = cosim_host.compile_host(tmp / "wine", cc=windows_bench.find_mingw() or "")
    specs = {}
    for kind, fmu in (("regular", plant), ("self-contained", standalone)):
        folder = tmp / "wine" / kind
        with zipfile.ZipFile(fmu) as zf:
            zf.extractall(folder)
        specs[kind] = tmp / "wine" / f"{kind}.spec"
        specs[kind].write_text(f"step 0.001\nstop 0\nfmu plant DrillstringPlant "
                               f"{windows_bench.windows_path(folder)}\n")
    envs = {"regular": {"DRILLCOSIM_PYTHON": windows_bench.windows_path(bench.python)},
            "self-contained": {}}
    times: dict[str, list[float]] = {k: [] for k in specs}
    for i in range(repeat + 1):
        for kind, spec in specs.items():
            out = tmp / "wine" / f"{kind}.csv"
            code, _rows, log = cosim_host.run_to_file(
                [bench.wine, str(exe), windows_bench.windows_path(spec),
                 windows_bench.windows_path(out)], out, bench.env(envs[kind]), tmp)
            found = re.search(r"host: fmi2Instantiate plant ([\d.]+) s", log)
            if code != 0 or found is None:
                raise RuntimeError(f"wine, {kind}: exit {code}\n{log[-2000:]}")
            if i > 0:  # the first: numba compiles the plant under wine (shared cache)
                times[kind].append(float(found.group(1)))
    med = {k: statistics.median(v) for k, v in times.items()}
    rows = ["", f"Under wine 8 (`--wine`: the win64 binaries, the mingw-built C host, median of "
            f"{repeat} after one warm-up each):", "",
            "| FMU | fmi2Instantiate | min | max |", "|---|---:|---:|---:|"]
    rows += [f"| {kind} | {med[kind]:.3f} s | {min(v):.3f} s | {max(v):.3f} s |"
             for kind, v in times.items()]
    rows += ["", f"Self-contained / regular under wine: "
             f"{med['self-contained'] / med['regular']:.2f}x."]
    return rows


if __name__ == "__main__":
    sys.exit(main())
