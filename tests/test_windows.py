"""The FMUs' win64 binaries in a Windows Python host (fmpy in the official CPython 3.13 for
Windows) under wine, against the same FMUs' linux64 binaries on Linux.

Every FMU the build writes carries both binaries (``fmu_src/platforms.py``). Here, in one
Windows Python process (its start and numpy/scipy/numba imports cost seconds under wine; the
plant's kernels are compiled there once per test run into a numba cache shared by the later
processes):

* the controllers alone (the Python strain controller's compiled step, the C controller) driven
  by a fixed strain sequence give the same bits as their linux64 binaries: nothing of the
  wrapper or the build differs between the platforms;
* closed loops co-simulated by fmpy (Jacobi, zero-order hold: ``support/windows_checks.py``) -
  the plant with the Python strain controller, the plant with the C controller, and the four-site
  scene's variants (``drillcosim build --scene four_sites``) - equal the same script's run of the
  linux64 binaries on Linux to :data:`RTOL_LIBM` of each signal's peak, and the Linux run equals
  our master's Jacobi result to 1e-12 (the script is the master's algorithm). Not to 1e-12: the
  plant's kernels call the C runtime's sin, cos and atan2, whose last bit differs between glibc
  and Windows' (here wine's) runtime for 2-20 % of arguments (measured by the ``libm`` check:
  never by more than one unit in the last place); the loop's dynamics carry these ulps to
  ~1e-11 of a peak in 0.1-1 s (3.3e-11 at 1 s, measured). A 1-ulp difference of one libm value
  is what a platform may differ by (C99 does not fix the last bit of sin); equal bits would need
  the same libm on both;
* ``fmpy.validation.validate_fmu`` finds no problem in any FMU, there and on Linux;

then in fresh Windows processes (a crash or a hang shows as the process's exit):

* a second process runs the plant from the first one's caches: the compiled steps come from
  the native image (llvmlite's MCJIT loading numba's COFF object code), not from a compile;
  then, in that same process, the misuse fuzzer (``support/fuzz_fmi.py``), short, on the
  plant, the strain controller and the C controller: no crash, no hang, never fmi2Fatal, a
  healthy instance reproduces its reference;
* two builds of the strain controller whose law differs (the second doubles the force) in one
  host, loaded from DLLs of one name in two folders: each runs its own code, in both orders.

The bench (``support/windows_bench.py``): under CI a missing wine, mingw-w64 or Windows Python is
a failure; elsewhere the tests skip with one line naming it. Durations are measured and printed
(``-s``): the compile under wine dominates.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from drillcosim.cosim.master.master import Master
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config
from drillcosim.fmu_src.build import REGISTRY, build_one
from support import windows_bench
from support.closed_loop import closed_loop

pytestmark = [pytest.mark.needs_cc, pytest.mark.interop, pytest.mark.slow]

HERE = Path(__file__).resolve().parent
CHECKS = HERE / "support" / "windows_checks.py"
ROOT = HERE.parent
STEP = 1e-4  #: [s]
STOP = 0.1  #: [s]: 1000 steps, the lateral signals well above round-off (at 0.02 s they are
#: ~1e-30 m: noise)
RTOL = 1e-12  #: of each signal's peak: our master vs the script, both on Linux
RTOL_LIBM = 1e-10  #: win64 vs linux64 (module docstring: the C runtime's last bits)
FUZZ_EXAMPLES = 8


@pytest.fixture(scope="module")
def bench() -> windows_bench.Bench:
    return windows_bench.require()


@pytest.fixture(scope="module")
def caches(windows_caches: dict[str, str]) -> dict[str, str]:
    """This run's caches of the Windows processes (conftest's ``windows_caches``: numba's, the
    stable package copies and their native images), shared with the other wine tests."""
    return windows_caches


def _system(loop_or_built) -> dict:
    """The jobs' loop description of a system (paths filled in by :func:`_jobs`)."""
    system = loop_or_built.system
    return {"fmus": {f.name: {"path": str(f.path), "parameters": dict(f.parameters)}
                     for f in system.fmus},
            "connections": [[*c.source.split(".", 1), *c.target.split(".", 1)]
                            for c in system.connections],
            "outputs": [o.split(".", 1) for o in loop_or_built.outputs],
            "step": STEP, "stop": STOP}


@pytest.fixture(scope="module")
def systems(bench, project_fmus: dict[str, Path], c_controller_fmu: Path,
            tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[dict, np.ndarray]]:
    """name -> (loop description, our master's rows on Linux)."""
    out = tmp_path_factory.mktemp("windows_loops")
    found = {}
    for name, controller in (("python", project_fmus["StrainController"]),
                             ("c", c_controller_fmu)):
        loop = closed_loop(project_fmus["DrillstringPlant"], controller, out / name,
                           step=STEP, stop=STOP)
        found[name] = (_system(loop), np.asarray(loop.data.tolist(), dtype=float))
    config = load_config("four_sites", {"cosim.step": STEP, "cosim.stop_time": STOP,
                                        "cosim.algorithm": "jacobi"})
    built = build_system(config, "fmu", fmu_dir=out / "four_sites_fmus")
    assert any("_four_sites" in Path(f.path).name for f in built.system.fmus)  # variants
    data = Master(built.system).simulate(STOP, built.outputs).data
    found["four_sites"] = (_system(built), np.asarray(data.tolist(), dtype=float))
    return found


def _jobs(systems: dict, where) -> list:
    jobs = []
    for name, (loop, _data) in systems.items():
        spec = json.loads(json.dumps(loop))
        for fmu in spec["fmus"].values():
            fmu["path"] = where(fmu["path"])
        jobs.append([name, "loop", spec])
    paths = sorted({f["path"] for loop, _d in systems.values() for f in loop["fmus"].values()})
    jobs.append(["validate", "validate", {"paths": [where(p) for p in paths]}])
    for name in ("python", "c"):  # the controllers alone; lag 0: no libm function in the law
        loop = systems[name][0]
        jobs.append([f"drive_{name}", "drive", {
            "fmu": where(loop["fmus"]["controller"]["path"]), "steps": 200, "step": STEP,
            "inputs": ["strain1_C", "strain1_E", "strain2_C", "strain2_E"],
            "parameters": {"lag_time_constant": 0.0, "gain": 1e9}}])
    jobs.append(["libm", "libm", {"n": 20000}])
    return jobs


def _run_checks(run, jobs: list, folder: Path, label: str) -> tuple[dict, float]:
    folder.mkdir(parents=True, exist_ok=True)
    spec = folder / f"{label}.json"
    spec.write_text(json.dumps(jobs))
    start = time.perf_counter()
    proc = run(spec)
    seconds = time.perf_counter() - start
    assert proc.returncode == 0, (label, proc.stdout[-2000:], proc.stderr[-4000:])
    results = json.loads(proc.stdout.strip().splitlines()[-1])
    failed = {k: v["error"] for k, v in results.items() if not v["ok"]}
    assert not failed, failed
    print(f"\n{label}: " + ", ".join(f"{k} {v['seconds']:.1f} s" for k, v in results.items()))
    return {k: v["result"] for k, v in results.items()}, seconds


@pytest.fixture(scope="module")
def linux(systems, tmp_path_factory) -> dict:
    """The checks with the linux64 binaries, in a fresh Linux Python (this one's venv)."""
    folder = tmp_path_factory.mktemp("linux_checks")
    results, _ = _run_checks(
        lambda spec: subprocess.run([sys.executable, str(CHECKS), str(spec)], cwd=ROOT,
                                    capture_output=True, text=True, timeout=1800),
        _jobs(systems, str), folder, "linux")
    return results


@pytest.fixture(scope="module")
def windows(bench, caches, systems, tmp_path_factory) -> dict:
    """The checks with the win64 binaries, in one Windows Python process under wine (the first
    of the run: the plant's kernels are compiled here)."""
    folder = tmp_path_factory.mktemp("windows_checks")
    results, seconds = _run_checks(
        lambda spec: bench.run_python(CHECKS, [windows_bench.windows_path(spec)], env=caches,
                                      timeout=3600),
        _jobs(systems, windows_bench.windows_path), folder, "windows")
    results["_seconds"] = seconds
    print(f"\nwindows checks: {seconds:.1f} s in one wine process; first fmi2Instantiate "
          f"(plant, compiling its kernels): {results['python']['instantiate_s']['plant']:.1f} s")
    return results


def _assert_equal_to_peak(name: str, got: np.ndarray, ref: np.ndarray, labels: list,
                          rtol: float = RTOL) -> float:
    """|got - ref| <= rtol * peak(|ref|) per column; returns the largest ratio found."""
    assert got.shape == ref.shape, (name, got.shape, ref.shape)
    peak = np.max(np.abs(ref), axis=0)
    excess = np.max(np.abs(got - ref), axis=0) - rtol * peak
    bad = {labels[j]: float(np.max(np.abs(got[:, j] - ref[:, j])) / max(peak[j], 1e-300))
           for j in np.flatnonzero(excess > 0)}
    assert not bad, (name, bad)
    ratios = np.max(np.abs(got - ref), axis=0) / np.where(peak > 0, peak, 1.0)
    return float(np.max(ratios))


@pytest.mark.parametrize("name", ["python", "c", "four_sites"])
def test_closed_loops_under_wine_equal_linux(name: str, systems, linux, windows) -> None:
    loop, master = systems[name]
    labels = ["time", *(".".join(o) for o in loop["outputs"])]
    lin = np.array(linux[name]["rows"])
    win = np.array(windows[name]["rows"])
    _assert_equal_to_peak(f"{name}: linux script vs our master", lin, master, labels)
    worst = _assert_equal_to_peak(f"{name}: win64 under wine vs linux64", win, lin, labels,
                                  RTOL_LIBM)
    print(f"\n{name}: win64 vs linux64, largest difference {worst:.2e} of a signal's peak")
    assert windows[name]["errors"] == [] and linux[name]["errors"] == []
    # a real loop: the bit force builds up (kN), the controller acts on the strains it reads
    column = {label: j for j, label in enumerate(labels)}
    assert np.max(np.abs(lin[:, column["plant.bit_axial_force"]])) > 1e3
    assert all(np.max(np.abs(lin[:, j])) > 0 for label, j in column.items()
               if label.startswith("controller.actuator"))


@pytest.mark.parametrize("name", ["python", "c"])
def test_the_controllers_give_the_same_bits_on_win64(name: str, linux, windows) -> None:
    win, lin = windows[f"drive_{name}"], linux[f"drive_{name}"]
    np.testing.assert_array_equal(np.array(win["rows"]), np.array(lin["rows"]))
    assert np.max(np.abs(np.array(lin["rows"]))) > 1e2  # forces of kN: a real law
    if name == "python":  # the compiled step ran on both (numba is loaded by the plant)
        assert set(win["compiled_sources"].values()) <= {"image", "numba"}
        assert any("controller" in k for k in win["compiled_sources"])


def test_the_c_runtimes_math_differs_in_the_last_bit_only(linux, windows) -> None:
    """What the plant's loops differ by: the C runtime's sin, cos, exp, atan2 (sqrt is exact)."""
    win, lin = np.array(windows["libm"]["values"]), np.array(linux["libm"]["values"])
    ulp = np.spacing(np.abs(lin))
    assert np.all(np.abs(win - lin) <= ulp), "a difference of more than one ulp"
    np.testing.assert_array_equal(win[:, 4], lin[:, 4])  # sqrt: correctly rounded everywhere
    share = np.mean(win != lin, axis=0)
    print(f"\nlast-bit differences win64 (wine's CRT) vs glibc: sin {share[0]:.1%}, cos "
          f"{share[1]:.1%}, exp {share[2]:.2%}, atan2 {share[3]:.1%}, sqrt {share[4]:.0%}")


def test_validate_fmu_is_clean_for_every_fmu_with_both_platforms(systems, linux,
                                                                 windows) -> None:
    for results in (linux["validate"], windows["validate"]):
        assert results and all(problems == [] for problems in results.values()), results
    for loop, _data in systems.values():
        for fmu in loop["fmus"].values():
            md = read_model_description(fmu["path"])
            ident = md.coSimulation.modelIdentifier
            import zipfile

            with zipfile.ZipFile(fmu["path"]) as zf:
                names = set(zf.namelist())
            assert {f"binaries/linux64/{ident}.so", f"binaries/win64/{ident}.dll"} <= names


@pytest.fixture(scope="module")
def second_process(bench, caches, systems, windows, tmp_path_factory) -> tuple[dict, float]:
    """One more Windows process on the first one's caches: the plant's loop again (10 steps),
    then the misuse fuzzer on the plant, the strain controller and the C controller (one wine
    process for both checks: its start and imports cost seconds under wine)."""
    loop = json.loads(json.dumps(systems["python"][0]))
    loop["stop"] = 10 * STEP
    for fmu in loop["fmus"].values():
        fmu["path"] = windows_bench.windows_path(fmu["path"])
    fmus = {"plant": systems["python"][0]["fmus"]["plant"]["path"],
            "controller": systems["python"][0]["fmus"]["controller"]["path"],
            "c_controller": systems["c"][0]["fmus"]["controller"]["path"]}
    jobs = [["again", "loop", loop]] + [
        [f"fuzz_{name}", "fuzz", {"fmu": windows_bench.windows_path(path),
                                  "examples": FUZZ_EXAMPLES, "seed": 1}]
        for name, path in fmus.items()]
    return _run_checks(
        lambda spec: bench.run_python(CHECKS, [windows_bench.windows_path(spec)], env=caches,
                                      timeout=1800), jobs, tmp_path_factory.mktemp("second"),
        "second")


def test_a_second_process_runs_the_compiled_steps_from_the_native_image(
        second_process, windows) -> None:
    """numba's cache (written by the first process) and the native image beside the package's
    stable copy: the second process loads machine code instead of compiling."""
    results, seconds = second_process
    again = results["again"]
    print(f"\nsecond wine process: {seconds:.1f} s; first fmi2Instantiate of the plant "
          f"{again['instantiate_s']['plant']:.2f} s (first process "
          f"{windows['python']['instantiate_s']['plant']:.1f} s); compiled steps from "
          f"{again['compiled_sources']}")
    assert set(again["compiled_sources"].values()) == {"image"}, again["compiled_sources"]
    np.testing.assert_array_equal(np.array(again["rows"]),
                                  np.array(windows["python"]["rows"])[:11])


def test_fuzzed_call_sequences_on_win64_never_crash_hang_or_go_fatal(second_process) -> None:
    results, _seconds = second_process
    fuzzed = {k: v for k, v in results.items() if k.startswith("fuzz_")}
    assert len(fuzzed) == 3, sorted(results)
    for name, report in fuzzed.items():
        assert report["examples"] >= FUZZ_EXAMPLES and report["calls_total"] > 0, (name, report)
        assert report["fatal"] == 0, (name, report)
        assert report["healthy_equal"] and report["reference_finite"], (name, report)


ORIGINAL = "            u = p.gain * eps\n"
PATCHED = "            u = 2.0 * p.gain * eps\n"


@pytest.fixture(scope="module")
def controller_builds(bench, tmp_path_factory) -> dict[str, Path]:
    """The strain controller as built, and built from a copy of ``controller/`` whose P law
    doubles the force (a real change of the shipped code)."""
    recipe = next(r for r in REGISTRY if r.name == "StrainController")
    src = tmp_path_factory.mktemp("patched_controller") / "controller"
    shutil.copytree(ROOT / "controller", src, ignore=shutil.ignore_patterns("__pycache__"))
    law = src / "strain_feedback.py"
    text = law.read_text()
    assert text.count(ORIGINAL) == 1  # the patch point still exists
    law.write_text(text.replace(ORIGINAL, PATCHED))
    import dataclasses

    patched = dataclasses.replace(recipe, vendored=((str(src), recipe.vendored[0][1]),
                                                    *recipe.vendored[1:]))
    return {"original": build_one(recipe, tmp_path_factory.mktemp("original_controller")),
            "patched": build_one(patched, tmp_path_factory.mktemp("patched_controller_fmu"))}


@pytest.mark.parametrize("first", ["original", "patched"])
def test_two_builds_in_one_windows_host_each_run_their_own_code(
        bench, caches, controller_builds, first, tmp_path) -> None:
    second = "patched" if first == "original" else "original"
    where = windows_bench.windows_path
    fmus = {first: where(controller_builds[first]), second: where(controller_builds[second]),
            f"{first}_2": where(controller_builds[first])}
    inputs = {"strain1_C": 1e-6, "strain1_E": -2e-6, "strain2_C": 3e-6, "strain2_E": 4e-6}
    results, _ = _run_checks(
        lambda spec: bench.run_python(CHECKS, [where(spec)], env=caches, timeout=900),
        [["builds", "two_builds", {"fmus": fmus, "inputs": inputs}]], tmp_path, "builds")
    out = results["builds"]
    rows = {k: np.array(v) for k, v in out["rows"].items()}
    np.testing.assert_array_equal(rows[f"{first}_2"], rows[first])
    np.testing.assert_array_equal(rows["patched"], 2.0 * rows["original"])
    assert np.all(np.abs(rows["original"]) > 0)
    controller_modules = [m for m in out["modules"] if m.startswith("_dcs_controller_")]
    assert len(controller_modules) == 2, out["modules"]  # one per build, each from its folder
    assert len({out["files"][m] for m in controller_modules}) == 2
