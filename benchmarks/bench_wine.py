"""Per-step cost of the FMUs' win64 binaries under wine next to their linux64 binaries, one run.

    python benchmarks/bench_wine.py [--steps 4000] [--repeat 3] [--fmu-dir build/fmus]

The same plain C host (``tests/support/fmi2_probe.c``; no Python in the process, so a Python FMU finds and
starts its Python as in Simulink or fmusim) is built with gcc for Linux and with mingw-w64 for
Windows (run under wine, the Windows bench of ``tests/support/windows_bench.py``). Per step:
``fmi2SetReal`` of the inputs, ``fmi2DoStep``, ``fmi2GetReal`` of every output.

* ``DrillstringPlant.fmu`` (0.25 ms steps: its compiled step runs without entering Python) in
  CPython 3.11 on Linux (this interpreter) and the official CPython 3.13 for Windows under wine;
* ``StrainControllerC.fmu`` (C99, no Python) as the reference of wine's own cost: if the plant's
  ratio wine/native is no larger than the C controller's, our wrapper adds nothing under wine.

Also measured: the first process of each side with empty caches (numba compiles the plant's
kernels and writes its cache and native image), and the second (loads them). The
configurations run interleaved ``--repeat`` times; the best block is reported (shared machine).
Prints a markdown section (for docs/performance.md).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from fmpy import read_model_description  # noqa: E402

from support import windows_bench  # noqa: E402

TIMER = ROOT / "tests" / "support" / "fmi2_probe.c"
FMI2 = ROOT / "fmu_src" / "wrapper" / "fmi2"


def _compile(cc: str, out: Path, libs: tuple[str, ...] = ()) -> Path:
    subprocess.run([cc, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", f"-I{FMI2}", "-o",
                    str(out), str(TIMER), *libs], check=True)
    return out


def _case(fmu: Path, folder: Path, step: float) -> dict:
    """Unzip ``fmu``; its library per platform, URI per side, GUID, inputs, outputs."""
    folder.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder)
    md = read_model_description(str(fmu))
    ident = md.coSimulation.modelIdentifier
    vr = {v.name: v.valueReference for v in md.modelVariables}
    inputs = [v.valueReference for v in md.modelVariables if v.causality == "input"
              and v.type == "Real"]
    outputs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    params = [f"r:{vr['max_internal_step']}={step}"] if "max_internal_step" in vr else []
    return {"linux": (str(folder / "binaries" / "linux64" / f"{ident}.so"),
                      (folder / "resources").as_uri()),
            "win": (windows_bench.windows_path(folder / "binaries" / "win64" / f"{ident}.dll"),
                    "file:///" + windows_bench.windows_path(folder / "resources")
                    .replace("\\", "/")),
            "guid": md.guid, "inputs": inputs, "outputs": outputs, "params": params}


def _args(case: dict, side: str, step: float, steps: int, repeat: int) -> list[str]:
    lib, uri = case[side]
    return [lib, uri, case["guid"], repr(step), str(steps), str(repeat),
            *map(str, case["inputs"]), "--", *map(str, case["outputs"]), "--", *case["params"]]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--fmu-dir", type=Path, default=ROOT / "build" / "fmus")
    parser.add_argument("--default-caches", action="store_true",
                        help="each side's default caches (the user's; under wine the prefix's), "
                             "warm from earlier runs, instead of empty ones: the per-step "
                             "figures without the minutes of a first compile under wine")
    args = parser.parse_args(argv)
    bench = windows_bench.prepare()
    work = Path(tempfile.mkdtemp(prefix="bench_wine_"))
    linux_timer = _compile("gcc", work / "timer", ("-ldl",))
    win_timer = _compile(windows_bench.find_mingw() or "x86_64-w64-mingw32-gcc",
                         work / "timer.exe")
    plant_step, c_step = 2.5e-4, 1e-4
    cases = {"plant": _case(args.fmu_dir / "DrillstringPlant.fmu", work / "plant", plant_step),
             "c": _case(args.fmu_dir / "StrainControllerC.fmu", work / "c", c_step)}
    steps = {"plant": (plant_step, args.steps), "c": (c_step, 50 * args.steps)}
    linux_env = {**os.environ, "DRILLCOSIM_PYTHON": sys.executable, "OPENBLAS_NUM_THREADS": "1"}
    win_env = {"DRILLCOSIM_PYTHON": windows_bench.windows_path(bench.python),
               "OPENBLAS_NUM_THREADS": "1"}
    if not args.default_caches:
        linux_env.update({"DRILLCOSIM_CACHE": str(work / "cache-linux" / "drillcosim"),
                          "NUMBA_CACHE_DIR": str(work / "cache-linux" / "numba")})
        win_env.update({
            "DRILLCOSIM_CACHE": windows_bench.windows_path(work / "cache-win" / "drillcosim"),
            "NUMBA_CACHE_DIR": windows_bench.windows_path(work / "cache-win" / "numba")})

    def run(side: str, name: str, n: int, repeat: int) -> tuple[float, float]:
        step = steps[name][0]
        start = time.perf_counter()
        if side == "linux":
            proc = subprocess.run([str(linux_timer), *_args(cases[name], side, step, n, repeat)],
                                  env=linux_env, capture_output=True, text=True,
                                  stdin=subprocess.DEVNULL, timeout=7200)
        else:
            proc = bench.run(win_timer, _args(cases[name], side, step, n, repeat), env=win_env,
                             timeout=7200)
        wall = time.perf_counter() - start
        if proc.returncode != 0:
            raise RuntimeError(f"{side} {name}: exit {proc.returncode}\n{proc.stderr[-3000:]}")
        timing = [ln for ln in proc.stdout.splitlines() if ln.startswith("TIMING ")]
        return (float(timing[-1].split()[1]) if timing else float("nan")), wall

    first = {side: run(side, "plant", 10, 0)[1] for side in ("linux", "win")}
    second = {side: run(side, "plant", 10, 0)[1] for side in ("linux", "win")}
    best: dict[tuple[str, str], float] = {}
    for _ in range(args.repeat):
        for name in ("plant", "c"):
            for side in ("linux", "win"):
                us, _wall = run(side, name, steps[name][1], 1)
                best[side, name] = min(best.get((side, name), 1e300), us)
    ratio = {name: best["win", name] / best["linux", name] for name in ("plant", "c")}
    label = {"plant": f"DrillstringPlant (Python {sys.version.split()[0]} / 3.13 for Windows; "
                      f"compiled step)", "c": "StrainControllerC (C99: wine's own cost)"}
    rows = {name: f"| {label[name]} | {steps[name][0] * 1e3:g} ms | {best['linux', name]:.3f} "
                  f"| {best['win', name]:.3f} | {ratio[name]:.2f} |" for name in ("plant", "c")}
    today = _dt.date.today().isoformat()
    flag = " --default-caches" if args.default_caches else ""
    caches = "the default (warm) caches" if args.default_caches else "empty caches"
    print(f"""
## The win64 binaries under wine vs the linux64 binaries ({today})

`python benchmarks/bench_wine.py --steps {args.steps} --repeat {args.repeat}{flag}` on {platform.node()}
({os.cpu_count()} cores, {platform.machine()}), wine 8 (Debian), the same C host
(`tests/support/fmi2_probe.c`, gcc / mingw-w64 -O2), best of {args.repeat} interleaved blocks.
Per step: fmi2SetReal of the inputs, fmi2DoStep, fmi2GetReal of every output.

| FMU | step | linux64 native [us/step] | win64 under wine [us/step] | wine / native |
|---|---|---|---|---|
{rows['plant']}
{rows['c']}

Plant ratio / C controller ratio: {ratio['plant'] / ratio['c']:.2f} (1 = our wrapper adds nothing
beyond wine's cost).

First process with {caches} (instantiate + 10 steps, wall; with empty caches numba
compiles the plant's kernels): native {first['linux']:.1f} s, under wine {first['win']:.1f} s
({first['win'] / first['linux']:.1f}x); second process (numba's cache / native image):
native {second['linux']:.1f} s, under wine {second['win']:.1f} s.
""")
    return 0


if __name__ == "__main__":
    sys.exit(main())
