"""The ``drillcosim`` command line: argument parsing on top of the public API
(:mod:`drillcosim.api`; the same run through either gives the same numbers).

Sub-commands: ``modes`` (modal analysis next to the analytic values and the paper's Table 1),
``scenes`` (list the shipped scenes), ``schema`` (the scene file schema), ``build`` (write the
FMUs), ``run`` (co-simulate a scene or an SSP file: results.csv, summary.json, plots), ``ssp``
(write a scene's system as an SSP file), ``sweep`` (gain x delay x step stability/benefit
table), ``calibrate`` (the paper's study: calibration, experiments, conclusion, report),
``design`` (an LQG or Smith-predictor lateral controller designed on the linearized plant,
written into a scene).

Exit codes: 0 done; 1 a run that stopped early (divergence: a one-line report) or failed; 2 bad
input (:class:`cosim.master.errors.UserError`: a scene, a key, a value, FMUs that do not fit,
an unwritable folder), reported in one line without a traceback (FMUs that do not fit: one line
per problem). Any other exception is an internal error: it keeps its traceback (exit code 1).
Warnings of the project (e.g. plant inputs no controller output feeds) are one line each.
"""

from __future__ import annotations

import argparse
import atexit
import errno
import json
import math
import os
import re
import sys
import threading
import warnings
from collections.abc import Sequence
from pathlib import Path

__all__ = ["main"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


#: the API's keyword (a ConfigError's ``given_as``) -> the option of the command line that gives it
_OPTION_OF = {"stop_time": "--stop-time", "step": "--step", "delay": "--delay", "gain": "--gain",
              "overrides": "--set", "plant_fmu": "--plant-fmu",
              "controller_fmu": "--controller-fmu"}
#: a negative number, also in exponent notation (argparse takes "-1e-4" for an option)
_NEGATIVE = re.compile(r"-(\d|\.\d)")


def _error_text(exc: BaseException) -> str:
    """A user error's one line; a value given on the command line is named by its option."""
    option = _OPTION_OF.get(getattr(exc, "given_as", None) or "")
    return f"{option}: {exc.detail}" if option else str(exc)


def _negative_values_joined(argv: Sequence[str]) -> list[str]:
    """``--opt -1e-4`` -> ``--opt=-1e-4``: argparse reads a negative number in exponent
    notation after an option as an option of its own ("expected one argument")."""
    out: list[str] = []
    for arg in argv:
        if out and _NEGATIVE.match(arg) and out[-1].startswith("--") and "=" not in out[-1]:
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def _user_errors() -> tuple[type[BaseException], ...]:
    from drillcosim.cosim.master.errors import UserError

    return (UserError,)


def _progress(args: argparse.Namespace) -> bool | None:
    return False if getattr(args, "no_progress", False) else None


def _cmd_modes(args: argparse.Namespace) -> int:
    from drillcosim.api import modes

    table = modes(args.scene, model=args.model)
    fm = table["modes"]
    if args.json:
        out = {k: {"frequency_rad_s": m["frequency_rad_s"], "damping_ratio": m["damping_ratio"]}
               for k, m in fm.items()}
        print(json.dumps(out, indent=2))
        return EXIT_OK
    spin = table["spin_rad_s"]
    print(f"scene {table['scene']} ({table['model']}, n = {table['n']}): first natural "
          "frequencies, linearized about the static equilibrium"
          + (f" spinning at {spin:g} rad/s (inertial-frame frequencies)" if spin else " at rest"))
    hdr = (f"{'mode':<10} {'ours [rad/s]':>13} {'analytic':>10} {'paper calc.':>12} "
           f"{'paper meas.':>12} {'zeta ours':>10} {'zeta paper':>11}")
    print(hdr)
    print("-" * len(hdr))
    for k, m in fm.items():
        a = m["analytic_rad_s"]
        a_s = f"{a:10.4g}" if not math.isnan(a) else f"{'-':>10}"
        print(f"{k:<10} {m['frequency_rad_s']:13.4f} {a_s} {m['paper_calculated_rad_s']:12.4g} "
              f"{m['paper_measured_rad_s']:12.4g} {100 * m['damping_ratio']:9.2f}% "
              f"{100 * m['paper_damping_ratio']:10.1f}%")
    print("analytic: rod pi c / (2 L) fixed-free (pi c / L when the bit is held axially); lateral: "
          "pinned multi-span Euler-Bernoulli beam over the top pin and stabilizers, no axial load")
    return EXIT_OK


def _cmd_schema(args: argparse.Namespace) -> int:
    from drillcosim.cosim.scenario.schema import scene_schema

    print(scene_schema(), end="")
    return EXIT_OK


def _cmd_scenes(args: argparse.Namespace) -> int:
    from drillcosim.api import list_scenes, load_scene

    for name in list_scenes():
        config = load_scene(name)
        print(f"{name:<28} {config.scene.model:<16} {config.scene.description}")
    return EXIT_OK


def _cmd_build(args: argparse.Namespace) -> int:
    from drillcosim.api import build_fmus, load_scene
    from drillcosim.cosim.master.errors import UserError
    from drillcosim.cosim.scenario.build import scene_recipes
    from drillcosim.cosim.scenario.scene_fmus import built_for_scene
    from drillcosim.fmu_src.platforms import select

    try:
        select(args.platforms)  # a bad --platforms is bad input: one line, exit 2
    except ValueError as exc:
        if args.platforms is not None:
            raise UserError(f"--platforms: {exc}") from None
    if args.scene:
        recipes = scene_recipes(load_scene(args.scene))
        built = build_fmus(args.out, scene=args.scene, platforms=args.platforms,
                           standalone=args.standalone)
        for instance, path in built.items():
            kind = ("built for the scene" if built_for_scene(recipes[instance])
                    else "the default build")
            print(f"built {path} ({instance}: {kind}{_self_contained(path)})")
        return EXIT_OK
    try:
        built = build_fmus(args.out, platforms=args.platforms,
                           standalone=args.standalone)  # "built <path>" per FMU
    except RuntimeError as exc:  # the C controller needs only a C compiler
        print(f"drillcosim build: {exc}", file=sys.stderr)
        return EXIT_FAILED
    for path in built.values() if args.standalone else [built["StrainControllerC"]]:
        print(f"built {path}{_self_contained(path)}")
    return EXIT_OK


def _self_contained(path: Path) -> str:
    """", self-contained: <platform> Python X (N MB)" for an FMU that carries runtimes."""
    from drillcosim.fmu_src.standalone import runtimes

    found = runtimes(path)
    if not found:
        return ""
    parts = [f"{p} Python {info['python']}" for p, info in found.items()]
    return (f", self-contained: {', '.join(parts)}; {path.stat().st_size / 1e6:.0f} MB, "
            f"{sum(int(i['bytes']) for i in found.values()) / 1e6:.0f} MB unpacked")


def _is_ssp(target: str) -> bool:
    path = Path(target)
    return path.suffix.lower() in (".ssp", ".ssd") or (path.is_dir() and
                                                       (path / "SystemStructure.ssd").is_file())


def _parse_set(items: Sequence[str]) -> dict:
    from drillcosim.cosim.scenario.config import parse_set

    return parse_set(items)


def _run_ssp(args: argparse.Namespace) -> int:
    from drillcosim.cosim.master.errors import UserError
    from drillcosim.cosim.scenario.ssp_run import simulate_ssp

    scene_only = [flag for flag, value in (("--delay", args.delay), ("--gain", args.gain),
                                           ("--set", args.set), ("--fmu-dir", args.fmu_dir),
                                           ("--plant-fmu", args.plant_fmu),
                                           ("--controller-fmu", args.controller_fmu),
                                           ("--engine", args.engine != "fmu"))
                  if value]
    if scene_only:
        raise UserError(f"{args.scene} is an SSP file: it takes --step, --stop-time and "
                        f"--out, not {', '.join(scene_only)} (options of scenes)")
    outcome = simulate_ssp(args.scene, stop_time=args.stop_time, step=args.step,
                           out_dir=args.out, progress=_progress(args))
    print(outcome.message, file=sys.stdout if outcome.completed else sys.stderr)
    return EXIT_OK if outcome.completed else EXIT_FAILED


def _cmd_run(args: argparse.Namespace) -> int:
    from drillcosim.api import build_system, load_scene
    from drillcosim.cosim.master.errors import FMI2_ERROR, CosimError

    if _is_ssp(args.scene):
        return _run_ssp(args)
    from drillcosim.cosim.scenario.plot_workers import PlotWorkers
    from drillcosim.cosim.scenario.result import plot_settings
    from drillcosim.cosim.scenario.simulate import simulate

    out = Path(args.out) if args.out is not None else Path("out") / Path(args.scene).stem
    # the figures' worker processes import matplotlib while the run steps, and draw the
    # figures with the rows so far (the feed)
    with PlotWorkers(0 if args.no_plots else None) as workers:
        try:
            config = load_scene(args.scene, stop_time=args.stop_time, step=args.step,
                                delay=args.delay, gain=args.gain, overrides=_parse_set(args.set),
                                plant_fmu=args.plant_fmu, controller_fmu=args.controller_fmu)
            built = build_system(config, args.engine, fmu_dir=args.fmu_dir)
            # the open-loop baseline of the figures: known now if cached, else run after
            want_baseline = not (args.no_plots or args.no_baseline)
            baseline = _baseline(config, cached_only=True) if want_baseline else None
            feed = workers.feed(plot_settings(config, baseline), config.cosim.stop_time)
            result = simulate(built, progress=_progress(args), csv_path=out / "results.csv",
                              observers=[feed] if feed is not None else (),
                              save_state=args.save_state, from_state=args.from_state)
        except CosimError as exc:  # failed before the first step: earlier files are kept
            if exc.call == "fmi2ExitInitializationMode" and exc.status == FMI2_ERROR:
                # the FMU rejected its parameters (its message names them): bad input
                print(f"drillcosim run: error: {exc}", file=sys.stderr)
                return EXIT_USAGE
            print(f"drillcosim run: failed: {exc}", file=sys.stderr)
            return EXIT_FAILED
        if want_baseline and baseline is None and len(result.data) >= 2:
            baseline = _baseline(config, cached_only=False, progress=_progress(args))
        files = result.save(out, plots=not args.no_plots, workers=workers, baseline=baseline)
    message = result.message(out, files)
    print(message, file=sys.stdout if result.completed else sys.stderr)
    if args.save_state is not None:
        print(f"checkpoint at {result.end_time:g} s: {args.save_state}" if result.completed
              else "no checkpoint written: the run did not reach its stop time",
              file=sys.stdout if result.completed else sys.stderr)
    if args.profile:
        print(result.profile_table())
    return EXIT_OK if result.completed else EXIT_FAILED


def _baseline(config, cached_only: bool, progress: bool | None = None):
    """The file of a closed-loop run's open-loop baseline: from the cache, or (not
    ``cached_only``) run now, once; None without one."""
    from drillcosim.cosim.scenario.baseline import baseline_cached, baseline_config, baseline_path

    if baseline_config(config) is None:
        return None
    if not baseline_cached(config):
        if cached_only:
            return None
        print("drillcosim run: running the open-loop baseline of the figures (once for this "
              "scene and these settings, then cached; --no-baseline skips it)", file=sys.stderr)
    return baseline_path(config, progress)


def _cmd_ssp(args: argparse.Namespace) -> int:
    from drillcosim.api import load_scene
    from drillcosim.cosim.scenario.ssp_run import write_scene_ssp

    config = load_scene(args.scene, step=args.step, stop_time=args.stop_time,
                        overrides=_parse_set(args.set), plant_fmu=args.plant_fmu,
                        controller_fmu=args.controller_fmu)
    written = write_scene_ssp(config, args.out, fmu_dir=args.fmu_dir,
                              omit_unsupported=args.omit_unsupported)
    exp = written.export
    if exp.omitted:
        print(f"drillcosim ssp: warning: written without: {'; '.join(exp.omitted)}",
              file=sys.stderr)
    print(f"wrote {exp.path} (system '{written.scene}'; Ecos: ecos simulate --path {exp.path} "
          f"--parameterSet {written.scene} ...)")
    return EXIT_OK


def _vary(items: Sequence[str]) -> dict[str, list[float]]:
    """``--vary KEY=LIST`` items -> ``{key path: values}`` (LIST as for --gain)."""
    from drillcosim.cosim.master.errors import UserError
    from drillcosim.cosim.scenario.config import split_assignment
    from drillcosim.cosim.study.grid import parse_list

    out: dict[str, list[float]] = {}
    for item in items:
        key, text = split_assignment(item, "--vary", "KEY=LIST",
                                     "controller.parameters.kd=0,1e4,1e5")
        if key in out:
            raise UserError(f"--vary {key}: given twice")
        out[key] = parse_list(text, f"--vary {key}")
    return out


def _cmd_sweep(args: argparse.Namespace) -> int:
    from drillcosim.api import sweep
    from drillcosim.cosim.study.grid import parse_list
    from drillcosim.cosim.study.sweep import judging_note, sweep_spec

    lists = {what: None if text is None else parse_list(text, flag)
             for what, flag, text in (("gains", "--gain", args.gain),
                                      ("delays", "--delay", args.delay),
                                      ("steps", "--step", args.step))}
    spec = sweep_spec(args.scene, **lists, stop_time=args.stop_time, engine=args.engine,
                      overrides=_parse_set(args.set), gain_key=args.gain_key,
                      vary=_vary(args.vary), plant_fmu=args.plant_fmu,
                      controller_fmu=args.controller_fmu)
    note = judging_note(spec)
    if note:
        print(f"drillcosim sweep: note: {note}", file=sys.stderr)
    out = args.out or f"out/sweep_{Path(args.scene).stem}"
    frame = sweep(spec, out=out, workers=args.workers, scheduler=args.scheduler,
                  progress=_progress(args), retry_errors=args.retry_errors,
                  branch=not args.no_branch)
    res = frame.attrs["outcome"]
    print(f"ran {res.n_run} of {res.n_points} points ({res.n_skipped} already done) in "
          f"{res.wall_time:.1f} s")
    print(res.summary())
    for line in res.notes:
        print(f"note: {line}")
    if args.maps:
        from drillcosim.cosim.study.maps import plot_maps

        for path in plot_maps(res.folder, predict=not args.no_prediction,
                              progress=_progress(args)):
            print(path)
    if res.n_errors:
        first = next(r for r in frame.to_dict("records") if r["status"] == "error")
        print(f"drillcosim sweep: {res.n_errors} point(s) failed; the first ({first['key']}): "
              f"{first['reason']}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from drillcosim.cosim.study.paper.stages import calibrate

    print(calibrate(args.stage, args.out, members=args.members, workers=args.workers,
                    scheduler=args.scheduler, progress=_progress(args),
                    figures=args.figures), end="")
    return EXIT_OK


def _cmd_doctor(args: argparse.Namespace) -> int:
    from drillcosim.cosim.master.errors import UserError
    from drillcosim.fmu_src.wrapper.doctor import NotAnFmuError, doctor_command

    try:
        return doctor_command(args.fmu)
    except NotAnFmuError as exc:
        raise UserError(str(exc)) from None


def _cmd_design(args: argparse.Namespace) -> int:
    from drillcosim.cosim.master.errors import UserError
    from drillcosim.cosim.study.control_design import LqgWeights, design_controller, write_scene

    if args.kind == "compare":
        return _cmd_compare(args)
    if not args.scene or not args.out:
        raise UserError(f"drillcosim design {args.kind}: give SCENE and --out SCENE.toml")
    joints = None
    if args.joints:
        try:
            joints = [int(j) for j in args.joints.split(",")]
        except ValueError:
            raise UserError(f"--joints {args.joints!r}: comma-separated joint numbers") from None
    options = {"force_limit": args.force_limit, "max_frequency": args.max_frequency}
    if args.kind == "lqg":
        options["weights"] = LqgWeights(args.deflection_scale, args.force_scale,
                                        args.force_noise, args.strain_noise)
    else:
        options["gain"] = args.gain
    d = design_controller(args.kind, args.scene, per_span=args.sites, joints=joints,
                          delay=args.delay, step=args.step, **options)
    scene, matrices = write_scene(d, args.out)
    print(d.summary())
    print(f"wrote {scene} and {matrices}")
    return EXIT_OK


def _cmd_compare(args: argparse.Namespace) -> int:
    from drillcosim.cosim.master.errors import UserError
    from drillcosim.cosim.study.control_design.compare import run_compare
    from drillcosim.cosim.study.control_design.compare_report import report
    from drillcosim.cosim.study.control_design.linear import linear_table

    if args.scene:
        raise UserError("drillcosim design compare takes no SCENE (the study's scenes are "
                        "fixed: docs/control_design.md); give --out DIR")
    out = args.out or "out/control_compare"
    if not args.report_only:
        linear_table(out, progress=_progress(args))
        if not args.linear:
            run_compare(out, workers=args.workers, scheduler=args.scheduler,
                        progress=_progress(args))
    print(report(out, args.figures), end="")
    return EXIT_OK


def _cmd_bench(args: argparse.Namespace) -> int:
    import importlib.util

    from drillcosim.cosim.master.errors import UserError

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "run_all.py"
    if not path.is_file():
        raise UserError(f"{path}: the benchmarks need a source checkout")
    spec = importlib.util.spec_from_file_location("drillcosim_bench_run_all", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.main((["--quick"] if args.quick else []) + (["--out", args.out] if args.out else []))


def _add_fmu_options(p: argparse.ArgumentParser, fmu_dir: bool = True) -> None:
    if fmu_dir:
        p.add_argument("--fmu-dir", metavar="DIR", help="folder of DrillstringPlant.fmu and "
                       "StrainController.fmu, used as is (default build/fmus, rebuilt when "
                       "stale)")
    p.add_argument("--plant-fmu", metavar="FMU", help="a plant FMU file (any maker) instead "
                   "of DrillstringPlant.fmu; checked against the controller by name")
    p.add_argument("--controller-fmu", metavar="FMU", help="a controller FMU file (any maker) "
                   "instead of StrainController.fmu, e.g. StrainControllerC.fmu; checked "
                   "against the plant by name")


def _add_engine_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--engine", choices=("fmu", "inprocess"), default="fmu",
                   help="fmu: plant + controller FMUs in the master (default); inprocess: the "
                        "same models as in-process slaves of the same master (no FMI boundary, "
                        "same numbers)")


class _VersionAction(argparse.Action):
    """``--version``: print ``drillcosim <version>`` and exit 0 (the version is looked up only
    then: :mod:`importlib.metadata` costs ~40 ms of every start otherwise)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS,
                 default: str = argparse.SUPPRESS, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        from drillcosim._version import __version__

        print(f"drillcosim {__version__}")  # to stdout, as argparse's own "version" action
        parser.exit()


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="drillcosim", description=__doc__.splitlines()[0])
    ap.add_argument("--version", action=_VersionAction, help="print the version and exit")
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("modes", help="first axial, torsional and lateral modes of a scene")
    p.add_argument("scene", nargs="?", default="table1_lateral_step",
                   help="scene name from scenes/ or a path (default: table1_lateral_step)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--model", choices=("full3d", "axial_torsional"),
                   help="override the scene's model")
    p.set_defaults(func=_cmd_modes)
    p = sub.add_parser("schema", help="print the scene file schema (markdown, docs/scenes.md)")
    p.set_defaults(func=_cmd_schema)
    p = sub.add_parser("scenes", help="list the shipped scenes")
    p.set_defaults(func=_cmd_scenes)
    p = sub.add_parser("build", help="build the FMUs")
    p.add_argument("--out", default=None, help="output folder (default: build/fmus of the "
                   "checkout, or the per-user FMU folder of an installed package; "
                   "`drillcosim run` looks there)")
    p.add_argument("--scene", metavar="SCENE", help="build the FMUs that run this scene (name "
                   "or path): plant and controllers for its layout (DrillstringPlant_<scene>, "
                   "StrainController_<scene>), or the default ones where they fit")
    p.add_argument("--platforms", metavar="LIST", default=None,
                   help="binary platforms of the FMUs, comma-separated: linux64,win64 (win64 "
                   "cross-compiled with mingw-w64); default: every one whose C compiler is "
                   "found, a skipped one named in one line")
    p.add_argument("--standalone", action="store_true", help="also write self-contained "
                   "copies into <out>/standalone/: each carries its own Python runtime for "
                   "each of its platforms (no Python needed on the target; the plant ~115 MB "
                   "for linux64, ~80 MB for win64), see docs/interop.md")
    p.set_defaults(func=_cmd_build)
    p = sub.add_parser("bench", help="plant work-precision benchmarks -> BENCHMARKS.md")
    p.add_argument("--quick", action="store_true", help="short horizons (< 3 min)")
    p.add_argument("--out", help="report path (default: BENCHMARKS.md of the checkout)")
    p.set_defaults(func=_cmd_bench)
    p = sub.add_parser("run", help="co-simulate a scene (plant FMU + controller FMU) or an "
                       "SSP 1.0 file")
    p.add_argument("scene", nargs="?", default="paper_closed_loop",
                   help="scene name from scenes/, a scene path, or an SSP file (.ssp, .ssd or "
                        "an unpacked SSP folder; takes --step, --stop-time, --out) (default: "
                        "paper_closed_loop)")
    p.add_argument("--stop-time", type=float, metavar="S", help="stop time [s]")
    p.add_argument("--step", type=float, metavar="H", help="communication step [s]")
    p.add_argument("--delay", type=float, metavar="TAU", help="actuator delay [s]")
    p.add_argument("--gain", type=float, metavar="K", help="controller gain [N per unit strain]")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key, e.g. cosim.sensor_delay=0.002 (value in TOML "
                        "syntax; repeatable)")
    p.add_argument("--out", metavar="DIR", help="output folder (default out/<scene>)")
    _add_engine_option(p)
    _add_fmu_options(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--profile", action="store_true",
                   help="print where the stepping loop's time went: per component its mean "
                        "and longest step and share, the master's own share, the real-time "
                        "factor (also in summary.json's telemetry)")
    p.add_argument("--save-state", metavar="FILE",
                   help="write a checkpoint of the whole system at the stop time (every FMU's "
                        "state and the master's: ticks, delay lines, held values)")
    p.add_argument("--from-state", metavar="FILE",
                   help="continue from a checkpoint (--save-state of the same scene, settings, "
                        "engine and build) to --stop-time; the same outputs, bit for bit, as "
                        "the run that was never interrupted")
    p.add_argument("--no-baseline", action="store_true",
                   help="figures without the open-loop baseline (a closed-loop run's figures "
                        "draw the scene with the controller off behind it; run once, cached)")
    p.set_defaults(func=_cmd_run)
    p = sub.add_parser("ssp", help="write a scene's system (FMUs included) as an SSP 1.0 file")
    p.add_argument("scene", help="scene name from scenes/ or a path")
    p.add_argument("--out", metavar="FILE", help="the .ssp file (default out/<scene>.ssp)")
    p.add_argument("--step", type=float, metavar="H", help="communication step [s]")
    p.add_argument("--stop-time", type=float, metavar="S", help="default stop time [s]")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key (as for run; repeatable)")
    _add_fmu_options(p)
    p.add_argument("--omit-unsupported", action="store_true",
                   help="write a system with delays, linear coupling or Gauss-Seidel stepping "
                        "without them (SSP 1.0 cannot hold them; listed as a warning)")
    p.set_defaults(func=_cmd_ssp)
    p = sub.add_parser("sweep", help="stability/benefit sweep over gain x delay x step x any "
                       "scene key (--vary)",
                       description="LIST: comma-separated values, start:stop:count, or "
                                   "log:start:stop:count (e.g. log:1e6:1e10:5). A point that "
                                   "the user must fix (FMUs that do not fit, an unknown "
                                   "parameter) stops the sweep before any point runs (exit "
                                   "2); a sweep with failed points exits 1 naming the first.")
    p.add_argument("scene", nargs="?", default="paper_closed_loop",
                   help="scene name from scenes/ or a path (default: paper_closed_loop)")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=LIST",
                   help="vary any scene key by its key path (repeatable; full factorial), "
                        "e.g. controller.parameters.kd=0,1e4,1e5 (a foreign FMU's own "
                        "parameter) or cosim.controller_sample_period=1e-3,2e-3")
    p.add_argument("--gain", metavar="LIST",
                   help="values of --gain-key (default: the scene's gain, not varied)")
    p.add_argument("--gain-key", metavar="TABLE.KEY",
                   help="the scene key the gains set: controller.gain [N per unit strain] "
                        "(default), or top_drive_controller.p_gain [N m s/rad] (the default "
                        "for a scene with a top-drive controller and no strain controller)")
    p.add_argument("--delay", metavar="LIST",
                   help="actuator delays [s] (cosim.actuator_delay; default: the scene's)")
    p.add_argument("--step", metavar="LIST",
                   help="communication steps [s] (cosim.step; default: the scene's)")
    p.add_argument("--stop-time", type=float, metavar="S",
                   help="stop time [s] (default: the scene's)")
    _add_engine_option(p)
    _add_fmu_options(p, fmu_dir=False)
    p.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes (default: all cores; 0: in this process)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="submit to this dask.distributed scheduler instead")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key for every point, e.g. cosim.algorithm='jacobi'")
    p.add_argument("--out", metavar="DIR", help="results folder (default out/sweep_<scene>); "
                   "re-running into it skips finished points")
    p.add_argument("--retry-errors", action="store_true", help="re-run points recorded as errors")
    p.add_argument("--no-branch", action="store_true",
                   help="run every closed-loop point from 0 s instead of continuing the points "
                        "identical up to the controller's switch-on from one checkpoint of "
                        "that prefix (the same table)")
    p.add_argument("--maps", action="store_true", help="also write the stability/benefit maps")
    p.add_argument("--no-prediction", action="store_true",
                   help="maps without the linear prediction overlay")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_sweep)
    p = sub.add_parser("calibrate", help="calibrate the paper's open quantities against its "
                       "Figs. 9-11, run its experiments (docs/paper_comparison.md)")
    p.add_argument("stage", choices=("coarse", "refine", "confirm", "all", "experiments",
                                     "conclusion", "report"),
                   help="coarse grid, one-at-a-time refinement, confirmation ensembles (all: "
                        "the three), the paper's experiments, its conclusion (sites per span x "
                        "gain x delay, maps), or the report (tables + PNGs)")
    p.add_argument("--out", default="out/calibration", metavar="DIR",
                   help="study folder, one resumable table per stage (default out/calibration)")
    p.add_argument("--members", type=int, metavar="K",
                   help="ensemble members per set (default: coarse 2, refine 4, confirm 12, "
                        "experiments 6)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes (default: all cores; 0: in this process)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="submit to this dask.distributed scheduler instead")
    p.add_argument("--figures", metavar="DIR",
                   help="report: folder of the PNGs and CSVs (default OUT/report)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_calibrate)
    p = sub.add_parser("design", help="design a lateral controller (LQG, or the Smith predictor "
                       "around the P law) on a scene's linearized plant and write it into a "
                       "scene; or run the comparison study (compare)")
    p.add_argument("kind", choices=("lqg", "predictor", "compare"),
                   help="compare: the P law, predictor and LQG over delay, simulated and "
                   "predicted (resumable table in --out DIR, default out/control_compare; "
                   "report: docs/control_design.md)")
    p.add_argument("scene", nargs="?", help="scene name or TOML file designed on (and "
                   "extended)")
    p.add_argument("--sites", type=int, metavar="N", help="actuator sites per span, evenly "
                   "spread (default: the scene's joints)")
    p.add_argument("--joints", metavar="J,J,...", help="explicit actuator joints")
    p.add_argument("--delay", type=float, metavar="S", help="actuator delay designed for [s] "
                   "(default: the scene's)")
    p.add_argument("--step", type=float, metavar="S", help="communication step = sample "
                   "period [s] (default: the scene's)")
    p.add_argument("--gain", type=float, default=1e8, metavar="K",
                   help="predictor: P-law gain [N/strain] (default 1e8)")
    p.add_argument("--deflection-scale", type=float, default=1e-3, metavar="M",
                   help="lqg: lateral displacement scale of the cost [m] (default 1e-3)")
    p.add_argument("--force-scale", type=float, default=1e4, metavar="N",
                   help="lqg: force scale of the cost [N] (default 1e4)")
    p.add_argument("--force-noise", type=float, default=1.0, metavar="N",
                   help="lqg: std of the unknown lateral force per body and axis [N] (default 1)")
    p.add_argument("--strain-noise", type=float, default=1e-7, metavar="E",
                   help="lqg: std of the strain noise [1] (default 1e-7)")
    p.add_argument("--force-limit", type=float, default=math.inf, metavar="N",
                   help="saturation: force magnitude <= N [N] (default: none)")
    p.add_argument("--max-frequency", type=float, default=1000.0, metavar="W",
                   help="design model: the plant's modes up to W [rad/s] (default 1000: the "
                   "lateral bending modes; inf: all); judged with all of them")
    p.add_argument("--out", metavar="SCENE.toml",
                   help="the scene to write; the matrices go to SCENE.json beside it "
                   "(compare: the study folder)")
    p.add_argument("--workers", type=int, default=1, metavar="N",
                   help="compare: worker processes (default 1; 0: this process)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="compare: a dask.distributed "
                   "scheduler instead of local workers")
    p.add_argument("--figures", metavar="DIR", help="compare: folder of the report's PNGs "
                   "and CSVs (default OUT/report)")
    p.add_argument("--report-only", action="store_true",
                   help="compare: only the report of the rows run so far")
    p.add_argument("--linear", action="store_true", help="compare: only the linear-regime "
                   "check (1.5 s runs: co-simulated vs predicted growth rate; ~1 min)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_design)
    p = sub.add_parser("doctor", help="which Python an FMU would run in on this machine, and why")
    p.add_argument("fmu", nargs="?", help="an FMU built by drillcosim (default: the built "
                   "DrillstringPlant.fmu); exit 0 if a host without Python finds one, 1 if not")
    p.set_defaults(func=_cmd_doctor)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``drillcosim`` console script; returns the exit code."""
    ap = _parser()
    args = ap.parse_args(_negative_values_joined(sys.argv[1:] if argv is None else argv))

    def one_line(message, category, filename, lineno, file=None, line=None):
        if category.__module__.startswith("drillcosim."):
            print(f"drillcosim {args.command}: warning: {message}", file=sys.stderr)
        else:
            previous(message, category, filename, lineno, file, line)

    previous = warnings.showwarning
    warnings.showwarning = one_line
    try:
        return int(args.func(args) or 0)
    except _user_errors() as exc:
        print(f"drillcosim {args.command}: error: {_error_text(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:  # read-only folder: bad input (2); disk full, I/O error: failure (1)
        print(f"drillcosim {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM) else \
            EXIT_FAILED
    except KeyboardInterrupt:
        print(f"drillcosim {args.command}: interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = previous


def console_main() -> int:
    """The ``drillcosim`` console script: :func:`main`, then a quick exit.

    After a run, Python's own finalization (tearing down numba's and llvmlite's modules and the
    FMUs' vendored packages, a last garbage collection) takes 0.2-0.6 s, as long as the whole
    start-up budget. When :func:`main` returns, everything it wrote is closed; the exit
    handlers still run (:mod:`atexit`: temporary folders, worker processes, logging), the
    standard streams are flushed, and the process ends with the exit code, skipping only the
    finalization. With a thread other than the main one still running (a library's worker),
    the exit is Python's usual one, which waits for it. An exception (an internal error) leaves
    as usual, with its traceback.
    """
    code = main()
    if threading.active_count() > 1:
        return code
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can be said
            pass
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console_main())
