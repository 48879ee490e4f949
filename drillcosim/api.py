"""The public Python API of drillcosim (``import drillcosim``).

>>> import drillcosim
>>> res = drillcosim.simulate("paper_closed_loop", stop_time=0.5, delay=1e-4)
>>> df = res.to_pandas()                 # index: time [s]; columns 'instance.variable'
>>> res.units["plant.strain1_C"], res.summary["spans"]["body11"]["peak_radial_deflection_m"]
>>> res.save("out/closed_loop")          # what ``drillcosim run`` writes

Every function takes scene keys by *key path* (``overrides={"cosim.sensor_delay": 1e-3,
"top_drive_controller.p_gain": 150.0}``; :mod:`cosim.scenario.config`), validated once; bad
input raises :class:`UserError` with one line naming the key and what is allowed. The command
line (``drillcosim``) is a thin layer on these functions: the same run gives the same numbers.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from drillcosim.analysis.modal import PAPER_TABLE1, analytic_reference, operating_modes
from drillcosim.cosim.master.errors import UserError
from drillcosim.cosim.scenario.build import ENGINES, build_system, scene_recipes
from drillcosim.cosim.scenario.config import SceneConfig, key_paths, load_config
from drillcosim.cosim.scenario.result import Result
from drillcosim.cosim.scenario.simulate import simulate as simulate_built
from drillcosim.cosim.study.grid import SweepSpec
from drillcosim.fmu_src.build import build_all, build_one, default_out
from drillcosim.fmu_src.build_c import build_c_controller
from drillcosim.plant import scene as _scene
from drillcosim.plant.model import DrillstringModel

__all__ = ["ENGINES", "Result", "SceneConfig", "UserError", "build_fmus", "list_scenes",
           "load_scene", "modes", "simulate", "sweep"]


def list_scenes() -> list[str]:
    """Names of the shipped scenes, sorted (``drillcosim scenes``)."""
    return _scene.list_scenes()


#: the keyword shortcuts of :func:`load_scene` and :func:`simulate`: keyword -> key path
SHORTCUTS = {"stop_time": "cosim.stop_time", "step": "cosim.step", "delay": "cosim.actuator_delay",
             "gain": "controller.gain"}


def _named(stop_time: float | None = None, step: float | None = None, delay: float | None = None,
           gain: float | None = None, overrides: Mapping[str, Any] | None = None
           ) -> tuple[dict[str, Any], dict[str, str]]:
    """The keyword shortcuts as key paths, then ``overrides`` (which win); and for each key
    path the keyword that gave it (``overrides`` for the mapping's), named in errors."""
    values = {"stop_time": stop_time, "step": step, "delay": delay, "gain": gain}
    over = {SHORTCUTS[k]: v for k, v in values.items() if v is not None}
    given = {SHORTCUTS[k]: k for k, v in values.items() if v is not None}
    more = key_paths(overrides)
    over.update(more)
    given.update(dict.fromkeys(more, "overrides"))
    return over, given


def load_scene(scene: str | Path = "paper_closed_loop", *, stop_time: float | None = None,
               step: float | None = None, delay: float | None = None, gain: float | None = None,
               overrides: Mapping[str, Any] | None = None,
               plant_fmu: str | Path | None = None,
               controller_fmu: str | Path | None = None) -> SceneConfig:
    """A scene with overrides, validated into its typed configuration.

    Parameters
    ----------
    scene : str or path
        A shipped scene's name (:func:`list_scenes`) or a scene file (``.toml``).
    stop_time, step, delay, gain : float, optional
        As for :func:`simulate`.
    overrides : mapping, optional
        Key paths -> values, e.g. ``{"cosim.step": 2.5e-4, "controller.gain": 1e8}``.
    plant_fmu, controller_fmu : path-like, optional
        FMU files (any maker) instead of the project's plant / strain controller.

    Returns
    -------
    SceneConfig
        ``.scene`` (the plant: ``.plant`` parameters, ``.model``), ``.controller``,
        ``.top_drive``, ``.cosim`` (step [s]; stop time, controller period, recording interval
        in steps).

    Raises
    ------
    UserError
        One line naming the file or key and what is allowed.
    """
    over, given = _named(stop_time, step, delay, gain, overrides)
    return load_config(scene, over, plant_fmu=plant_fmu, controller_fmu=controller_fmu,
                       given_as=given)


def simulate(scene: str | Path = "paper_closed_loop", *, stop_time: float | None = None,
             step: float | None = None, delay: float | None = None, gain: float | None = None,
             overrides: Mapping[str, Any] | None = None, engine: str = "fmu",
             outputs: Sequence[str] | None = None, progress: bool | None = False,
             fmu_dir: str | Path | None = None, plant_fmu: str | Path | None = None,
             controller_fmu: str | Path | None = None,
             csv_path: str | Path | None = None, save_state: str | Path | None = None,
             from_state: str | Path | None = None) -> Result:
    """Co-simulate a scene: plant and controllers through the master.

    Parameters
    ----------
    scene : str or path
        A shipped scene's name (:func:`list_scenes`) or a scene file.
    stop_time : float, optional
        [s], an integer multiple of the step (``cosim.stop_time``; default the scene's).
    step : float, optional
        Base communication step H [s] (``cosim.step``).
    delay : float, optional
        Actuator delay [s] (``cosim.actuator_delay``), >= 0.
    gain : float, optional
        Strain controller gain [N per unit strain] (``controller.gain``; does not enable a
        disabled controller).
    overrides : mapping, optional
        Any scene key by key path, e.g. ``{"cosim.sensor_delay": 1e-3}``; applied after the
        keywords above.
    engine : {"fmu", "inprocess"}
        The FMUs (built on demand), or the same models in process (same numbers, no FMI
        boundary).
    outputs : sequence of str, optional
        ``'instance.variable'`` to record (default: deflections, strains, forces, bit and drive).
    progress : bool or None
        Progress bar (None: only on a terminal).
    fmu_dir : path-like, optional
        Folder of the project's FMUs (default ``build/fmus``).
    plant_fmu, controller_fmu : path-like, optional
        FMU files (any maker) instead of the project's; checked against the others by name.
    csv_path : path-like, optional
        Also stream the recorded rows to this CSV while running (``drillcosim run`` does).
    save_state : path-like, optional
        Write a checkpoint of the whole system (every component's state and the master's) at
        the stop time to this file.
    from_state : path-like, optional
        Continue from this checkpoint to ``stop_time`` instead of starting at 0 s: the same
        outputs, bit for bit, as the run that was never interrupted. A checkpoint of another
        scene, settings, build, FMU or version, or a damaged one, is refused (one line).

    Returns
    -------
    Result
        ``.to_pandas()`` (index time [s], columns ``instance.variable``), ``.units``,
        ``.summary``, ``.plot()``, ``.save(folder)``; ``.failure`` says why a run stopped early
        (divergence: time and quantity).

    Raises
    ------
    UserError
        Bad input (scene, key, value, FMUs that do not fit): one line per problem.
    cosim.master.errors.CosimError
        The run failed before its first step (e.g. an FMU rejected its parameters).
    """
    config = load_scene(scene, stop_time=stop_time, step=step, delay=delay, gain=gain,
                        overrides=overrides, plant_fmu=plant_fmu, controller_fmu=controller_fmu)
    built = build_system(config, engine, fmu_dir=fmu_dir)
    return simulate_built(built, outputs=outputs, progress=progress, csv_path=csv_path,
                          save_state=save_state, from_state=from_state)


def sweep(scene: str | Path | SweepSpec = "paper_closed_loop", *,
          gains: Sequence[float] | None = None, delays: Sequence[float] | None = None,
          steps: Sequence[float] | None = None, vary: Mapping[str, Sequence[Any]] | None = None,
          stop_time: float | None = None, gain_key: str | None = None,
          overrides: Mapping[str, Any] | None = None, engine: str = "fmu",
          plant_fmu: str | Path | None = None, controller_fmu: str | Path | None = None,
          out: str | Path | None = None, workers: int | None = 0, scheduler: Any = None,
          progress: bool | None = False, retry_errors: bool = False, branch: bool = True,
          **options: float):
    """Stability and benefit sweep, one co-simulation per point: gain x delay x step x any
    other scene keys (``vary``), full factorial, plus open-loop references.

    Parameters
    ----------
    scene : str, path or SweepSpec
        The scene; or a sweep planned already (:func:`cosim.study.sweep.sweep_spec`, as
        ``drillcosim sweep`` does), then only the run's arguments (``out``, ``workers``, ...)
        apply.
    gains : sequence of float, optional
        Values of ``gain_key`` (default: the scene's gain, not varied).
    delays : sequence of float, optional
        Actuator delays [s] (default: the scene's).
    steps : sequence of float, optional
        Communication steps [s] (the controllers sample at them; default: the scene's).
    vary : mapping of str -> sequence, optional
        Any other scene keys by key path and their values, e.g.
        ``{"controller.parameters.kd": [0.0, 1e4, 1e5]}`` (a foreign controller FMU's own
        parameter) or ``{"cosim.controller_sample_period": [1e-3, 2e-3]}``.
    stop_time : float, optional
        [s]; default the scene's.
    gain_key : str, optional
        ``controller.gain`` (default), or ``top_drive_controller.p_gain`` [N m s/rad] (the
        default for a scene with a top-drive controller and no strain controller).
    overrides : mapping, optional
        Scene keys by key path for every point.
    engine : {"fmu", "inprocess"}
    plant_fmu, controller_fmu : path-like, optional
        FMU files (any maker) instead of the project's.
    out : path-like, optional
        Results folder (``results.csv``, ``results.parquet``, ``sweep.json``: the sweep and
        what ran each instance; re-running into it skips finished points). Default: a
        temporary folder, removed afterwards.
    workers : int or None
        Local worker processes (0: in this process; None: all cores).
    scheduler : str or distributed.Client, optional
        A dask.distributed cluster instead.
    progress : bool or None
    retry_errors : bool
        Re-run points recorded as errors.
    branch : bool
        Closed-loop points identical up to the controller's switch-on (e.g.
        ``paper_switch_on_25s``) continue from one checkpoint of that prefix instead of each
        running it (the same table; ``branch_time`` says where a point branched).
    **options
        Point metric options (:class:`cosim.study.point.PointOptions`: ``fit_fraction``,
        ``envelope_window`` [s], ``rms_fraction``, ``force_cap`` [N], ``highpass`` [rad/s]).

    Returns
    -------
    pandas.DataFrame
        One row per point (open-loop references first): identity columns (``kind``, ``gain``,
        ``delay`` [s], ``step`` [s], ``varied``: the other axes' values, JSON), metrics
        (``growth_rate`` [1/s], ``rms_long`` [m], ...) and the ``verdict`` (stable / unstable /
        undecided / error). ``.attrs["outcome"]`` holds the run's counts
        (:class:`cosim.study.sweep.SweepOutcome`).

    Raises
    ------
    UserError
        A bad value, or a point the user must fix (FMUs that do not fit, an unknown or
        out-of-range parameter), before any point runs.
    """
    import pandas as pd  # an optional heavy import: only here

    # the study (scipy.signal, scipy.stats: ~0.5 s) only here: `drillcosim run` never needs it
    from drillcosim.cosim.study.sweep import execute_sweep, sweep_spec
    from drillcosim.cosim.study.table import read_table

    if isinstance(scene, SweepSpec):
        spec = scene
    else:
        spec = sweep_spec(scene, gains, delays, steps, stop_time, engine, overrides, options,
                          gain_key, vary, plant_fmu=plant_fmu, controller_fmu=controller_fmu)
    with tempfile.TemporaryDirectory(prefix="drillcosim_sweep_") as tmp:
        folder = Path(out) if out is not None else Path(tmp)
        outcome = execute_sweep(spec, folder, workers=workers, scheduler=scheduler,
                                progress=progress, retry_errors=retry_errors, branch=branch)
        keys = {p.key for p in spec.points()}
        rows = [r for r in read_table(folder) if r["key"] in keys]
    frame = pd.DataFrame(rows)
    frame.attrs["outcome"] = outcome
    return frame


def modes(scene: str | Path = "table1_lateral_step", *, model: str | None = None,
          overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """First axial, torsional and lateral natural frequencies of a scene's plant, next to the
    analytic value and the paper's Table 1 (``drillcosim modes``).

    Linearized about the static equilibrium (spinning with the top drive, if it turns; the
    frequencies are then the inertial frame's).

    Parameters
    ----------
    scene : str or path
    model : {"full3d", "axial_torsional"}, optional
        Instead of the scene's model.
    overrides : mapping, optional
        Scene keys by key path.

    Returns
    -------
    dict
        ``scene``, ``model``, ``n`` (bodies), ``spin_rad_s``, and ``modes``: per kind
        (``axial``, ``torsional``, ``lateral``) ``frequency_rad_s``, ``damping_ratio`` [1],
        ``analytic_rad_s`` (NaN where none), ``paper_calculated_rad_s``,
        ``paper_measured_rad_s``, ``paper_damping_ratio``.
    """
    if model not in (None, "full3d", "axial_torsional"):
        raise UserError(f"model = {model!r} is not allowed; allowed: full3d, axial_torsional")
    sc = load_config(scene, overrides).scene
    kind = model or sc.model
    built = DrillstringModel(sc.plant, kind)
    first = {}
    for md in operating_modes(sc.plant, kind):
        first.setdefault(md.kind, md)
    ref = analytic_reference(built)
    table = {k: {"frequency_rad_s": m.frequency_rad_s, "damping_ratio": m.damping_ratio,
                 "analytic_rad_s": ref[k],
                 "paper_calculated_rad_s": PAPER_TABLE1[k]["calculated"],
                 "paper_measured_rad_s": PAPER_TABLE1[k]["measured"],
                 "paper_damping_ratio": PAPER_TABLE1[k]["damping_ratio"]}
             for k in ("axial", "torsional", "lateral") if (m := first.get(k)) is not None}
    return {"scene": sc.name, "model": kind, "n": built.n,
            "spin_rad_s": sc.plant.top_drive.rotary_speed, "modes": table}


def build_fmus(out: str | Path | None = None, *, scene: str | Path | None = None,
               platforms: str | Sequence[str] | None = None,
               standalone: bool = False) -> dict[str, Path]:
    """Build the FMUs (``drillcosim build``).

    Parameters
    ----------
    out : path-like, optional
        Target folder (default ``build/fmus`` of a checkout, else a per-user folder).
    scene : str or path, optional
        Build the FMUs that run this scene (plant and controllers for its layout, or the
        default ones where they fit) instead of the default set.
    platforms : str or sequence of str, optional
        Binary platforms, e.g. ``"linux64,win64"``; default: this machine's and every other
        one whose C compiler is found (a skipped one is named in one printed line).
    standalone : bool
        Also write self-contained copies that carry their own Python runtime for each of their
        platforms (:mod:`drillcosim.fmu_src.standalone`) into ``<out>/standalone/``; those
        are returned.

    Returns
    -------
    dict of str -> Path
        By instance (``plant``, ``controller``, ...) for a scene, else by FMU name.

    Raises
    ------
    RuntimeError
        No C compiler for ``StrainControllerC.fmu`` (the others are built), or no runtime can
        be made (``standalone``: the building Python has no shared libpython, a download
        failed).
    ValueError
        An unknown platform, or one named whose compiler is missing.
    """
    from drillcosim.fmu_src.platforms import select

    folder = Path(out) if out is not None else default_out()
    try:
        selection = select(platforms)
    except ValueError as exc:
        if platforms is not None:
            raise
        raise RuntimeError(f"building the FMUs needs a C compiler: {exc}") from None
    if scene is not None:
        if selection.note():
            print(selection.note())
        built = {instance: build_one(recipe, folder, selection)
                 for instance, recipe in scene_recipes(load_config(scene)).items()}
    else:
        built = {Path(p).stem: Path(p) for p in build_all(folder, platforms=selection)}
        built["StrainControllerC"] = build_c_controller(folder, platforms=selection)
    if standalone:
        from drillcosim.fmu_src.standalone import make_standalone

        built = {key: make_standalone(path, folder / "standalone" / path.name)
                 for key, path in built.items()}
    return built
