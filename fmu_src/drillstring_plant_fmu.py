"""pythonfmu adapter: the drillstring plant as an FMI 2.0 co-simulation FMU.

This file is the FMU's slave module. It holds no physics: ``exitInitializationMode``
builds ``Scene -> PlantParams -> DrillstringModel -> PlantSimulator`` from the
vendored copy of the ``plant`` package, and ``doStep`` runs the simulator's compiled
step (``plant.compiled_step``: the C wrapper calls it without entering Python; it reads
the inputs and writes the outputs in the shared buffers) or, as the reference and for
what the compiled step leaves to Python (the first step of a step size, a diverged
instance, ``DRILLCOSIM_COMPILED_STEP=0``), ``do_step``: it sets the inputs, calls
``PlantSimulator.do_step`` and writes the outputs; both give the same bits. The build (``fmu_src/build.py``)
ships ``plant/`` as ``resources/_dcs_plant_0_1_0/`` and the shipped scenes as
``resources/scenes/*.toml``. The FMU needs numpy, scipy and numba in the Python it runs in.

Numba cache in a stable place
-----------------------------
The kernels and the compiled step are numba functions with ``cache=True``; numba keys its
cache by the source path, and fmpy (like most importers) unzips every FMU into a new temporary
folder. At import the vendored package is therefore copied once to a per-user folder named by
its content hash and imported from there (``slave_support.vendored``: ``$DRILLCOSIM_CACHE``,
default ``~/.cache/drillcosim``); if that folder cannot be written, a warning is logged at
instantiation and every new unzip folder recompiles.

Beside that copy the FMU keeps two things a later process reuses, so that one needs no numba
set-up at all (~0.25 s): the *native image* of the compiled entry points (the machine code numba
cached, loaded with llvmlite: ``slave_support.native``), and the spectral radius of each model
built (``plant.model.SPECTRAL_RADII``: the automatic method's stable step, a Jacobian and an
eigenvalue problem otherwise; one file per Python and numpy version). The outputs at
initialization and the automatic method's first step of a step size run through the compiled
entry points too.

The wrapper imports this module once per process (``sys.modules``) and the first
instance's unzip folder may be deleted while later instances run: module-level code
therefore reads no files, and each instance finds the scenes through its own
``resources`` argument.

Interface (value references follow the registration order)
----------------------------------------------------------
inputs (Real, N, continuous, start 0):
    actuator1_force_C, actuator1_force_E, actuator2_force_C, actuator2_force_E.
    Site 1 = long span, site 2 = short span; a force > 0 opposes positive strain
    (compressive at D / F, tensile at C / E). Held constant over each step.
outputs (Real, continuous, initial calculated):
    the outputs of the full 3D model with the default scene (2 contact bodies,
    2 actuator sites) in the model's order: ``body11_X`` ... ``strain1_C`` ...
    ``total_energy`` (the class's port table ``PORTS``, from ``plant.signals``).
    Values at the communication point reached by the last ``doStep``; no direct
    feedthrough (an input changes the outputs only through the next ``doStep``;
    ``actuatorK_power`` uses the force held over the last step).
parameters (all variability fixed: set before ``fmi2ExitInitializationMode``):
    ``scene`` (String, default "paper_open_loop"): a shipped scene name or a path
    to a scene TOML file (its ``extends`` names resolve among the shipped scenes);
    ``model`` (String "auto" | "full3d" | "axial_torsional", default "full3d":
    "auto" keeps the scene's model); ``max_internal_step`` [s] (0 = automatic: per
    communication step the method and stable step of ``DrillstringModel.method_for_step``,
    or one exponential Euler step a communication step for a linear axial-torsional scene
    (``DrillstringModel.exponential_exclusions`` empty); a value > 0 means RK4 at that step
    bound, and larger values may diverge); and every scalar field of
    ``PlantParams`` flattened as ``section.field`` (``pipe.n_segments``,
    ``contact.stiffness``, ``gravity``, ...), Real/Integer/Boolean with the unit
    and description of the field metadata and start = the ``PlantParams`` default.

Parameter rule: the scene is loaded first; then every FMU parameter whose value
differs from its start value overrides the scene's value (the override goes
through the scene validation, so messages name the parameter). Setting a
parameter to its start value therefore never overrides the scene (importers that
write all start values change nothing); to return a parameter to its default
where the scene sets another value, use a scene file that ``extends`` the
shipped scene. Tuple-valued fields (``stabilizers.heights``, ``contact.bodies``,
``actuators.joints``) and ``[[loads]]`` are scene-only.

The declared outputs need the 3D model with contact bodies 11 and 26 and two
actuator sites. If the chosen scene, model or parameters give a model lacking any
of them (``model = "auto"`` or ``"axial_torsional"`` resolving to the
axial-torsional chain, contact disabled, other contact bodies), initialization
fails with an error naming the missing outputs; they are never silently zero. A
model whose inputs differ from the declared ones (another number of sites, a
top-drive input) is refused the same way.

Built for a scene (a variant)
-----------------------------
``drillcosim build --scene SCENE`` builds this adapter for another layout: a generated
subclass ``DrillstringPlant_<scene>`` (``fmu_src/build.py``, "Variants") whose class
attribute ``LAYOUT`` holds the scene name (the ``scene`` parameter's start), the model kind
(the ``model`` parameter's start), whether the extended outputs are listed, and the inputs
and outputs (name, unit, description) of that scene's model. :meth:`DrillstringPlant.__init_subclass__`
derives the variable tables from it; nothing else differs. The inputs are those that act on
the model (:attr:`plant.model.DrillstringModel.acting_inputs`: no actuator forces for the
axial-torsional chain, which has no bending); the model's other inputs are held at 0.

Parameter errors name the FMU variable: a value set through the FMI API is checked
against its own range first (``pipe.n_segments = 1 is out of range: allowed [2, 2000]``,
with the scene's other values of that section); only a conflict with the scene's
other sections (e.g. contact bodies beyond a reduced ``pipe.n_segments``) names the scene
file, together with the FMU variables set.

Error handling (the wrapper's status protocol, see ``fmu_src/slave_support``)
------------------------------------------------------------------------------
* invalid parameter (out of range, wrong ``scene`` / ``model``, missing outputs):
  fmi2ExitInitializationMode -> fmi2Error with the message naming it; the instance stays
  in initialization mode (a doStep is refused): correct the parameters and call it again,
  or reset;
* non-finite input, non-positive or too large step, wrong communication point ->
  fmi2Error from that doStep, state unchanged; doStep before initialization ->
  fmi2Error (checked by the wrapper itself);
* divergence (non-finite state, lateral deflection > 1 m, tilt > 0.5 rad, speed >
  1e4) -> fmi2Discard naming time, quantity and value, now and for every later
  doStep until an FMU state saved before is restored (``fmi2SetFMUstate``) or the
  FMU is reset;
* unknown value reference, wrong type, setting an output or a fixed parameter after
  initialization, an invalid FMU state -> fmi2Error from that get/set/setFMUstate
  call itself (a get returns NaN / 0 / false / "" for it; a set refused for one value
  reference sets none of the call's values);
* an unexpected exception -> fmi2Error, the instance stays usable. Never fmi2Fatal.

The inputs and outputs live in the shared buffers ``self.inputs`` / ``self.outputs``: in
step mode the wrapper moves them without Python, and a doStep is one call of the compiled
step (:meth:`_fmi2_compiled_step`; its failure codes come back to
:meth:`_fmi2_compiled_step_failed`, which reports the status and message ``do_step`` gives).

FMU state (the rules of ``slave_support.state``): the registered variables plus the
simulator's time, state vector and held inputs, the divergence note and the start time
(JSON-safe floats, so serialisation is bit-exact). Restoring a state whose parameters
differ from the instance's builds their model first (refused, as at initialization, if
they are invalid) and checks the state vector against it; nothing is applied unless all
of it fits. A state of a running plant must carry its simulator state.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
import sys
import traceback
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import _dcs_slave_support_0_1_0 as support
import numpy as np

#: Scene loaded unless the ``scene`` parameter names another one.
DEFAULT_SCENE = "paper_open_loop"


#: The plant package, from its stable copy (numba's cache needs a fixed path).
_PLANT, _IMPORT_WARNING = support.vendored.import_vendored(
    "_dcs_plant_0_1_0", __file__, ("params", "scene", "model", "simulator", "signals"))
_scene_mod, _model_mod, _sim_mod = _PLANT.scene, _PLANT.model, _PLANT.simulator
MODEL_CHOICES: tuple[str, ...] = _scene_mod.MODEL_CHOICES
#: The scalar parameters: (port, section, key) rows of ``plant.scene.parameter_table``.
PARAMETERS = _scene_mod.parameter_table()


#: The spectral radii of the models built (``plant.model.SPECTRAL_RADII``), kept beside the
#: stable copy per Python and numpy version (the eigenvalue solver's): a second process skips
#: the Jacobian and the eigenvalue problem.
_RADII_FILE = (f"spectral-radii-py{sys.version_info[0]}{sys.version_info[1]}"
               f"-numpy-{np.__version__}.json")


def _with_spectral_memo(make: Any) -> Any:
    """``make()`` with the spectral radii memo filled from, and new ones saved to, its file."""
    radii = _model_mod.SPECTRAL_RADII
    path = support.vendored.cache_file(_PLANT, _RADII_FILE)
    radii.update({k: v for k, v in support.vendored.read_memo(path).items() if k not in radii})
    known = set(radii)
    made = make()
    if set(radii) - known:
        support.vendored.write_memo(path, radii)
    return made


def _compiled_entries() -> bool:
    """Whether compiled steps are on; the first call in the process gives the plant's compiled
    entry points their addresses: from the native image beside the stable copy when there is
    one (no numba set-up), else from numba (which writes the image; ``slave_support.native``)."""
    cs = importlib.import_module(".compiled_step", _PLANT.__name__)
    if not cs.enabled():
        return False
    support.provide(_PLANT, cs)
    return True


def scenes_folder(resources: str | None = None) -> Path:
    """Shipped scenes: ``<resources>/scenes`` of this instance; at build time ``scenes/``.

    pythonfmu 0.7.0 re-executes this module's code at every instantiation, and a
    Python exception there crashes the host (segfault, reproduced with fmpy after
    the first unzip folder was deleted). So module-level code touches no files;
    the folder comes from the instance's ``resources`` argument.
    """
    if resources:
        return Path(resources) / "scenes"
    here = Path(__file__).resolve().parent
    for cand in (here / "scenes", here.parent / "scenes"):
        if cand.is_dir():
            return cand
    return here / "scenes"


_INPUT_ROWS, _OUTPUT_ROWS = _scene_mod.default_io_rows()


class DrillstringPlant(support.DcsSlave):
    """FMI 2.0 co-simulation adapter of :class:`plant.simulator.PlantSimulator`."""

    author = "drillcosim"
    version = "0.1.0"
    description = (
        "Drillstring vibration plant (3D bond-graph rigid-segment model): inputs are the "
        "bending actuator forces at 2 sites [N], outputs strains, contact, boundary forces. "
        "Parameters: scene (shipped name or TOML path) first, then every parameter set to a "
        "value different from its start overrides the scene")

    #: The layout: start of ``scene`` and ``model``, extended outputs (True: listed whatever
    #: the parameters; False: as the model decides), inputs and outputs (name, plant unit,
    #: description). A variant sets ``LAYOUT`` (a dict of these) and gets them derived.
    SCENE: ClassVar[str] = DEFAULT_SCENE
    MODEL: ClassVar[str] = "full3d"
    EXTENDED: ClassVar[bool] = False
    #: The port table: the inputs and outputs of the layout, then the run parameters and the
    #: scalar parameters (``plant.signals.io_ports``, ``plant.scene.run_ports``,
    #: ``plant.scene.parameter_table``); a variant's from its ``LAYOUT``.
    PORTS: ClassVar[tuple[Any, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A variant: the class tables from its ``LAYOUT`` (see "Built for a scene")."""
        super().__init_subclass__(**kwargs)
        layout = cls.__dict__.get("LAYOUT")
        if layout is None:
            return
        cls.SCENE, cls.MODEL = str(layout["scene"]), str(layout["model"])
        if cls.MODEL not in MODEL_CHOICES:
            raise ValueError(f"{cls.__name__}: LAYOUT model {cls.MODEL!r} is not one of "
                             f"{MODEL_CHOICES}")
        cls.EXTENDED = bool(layout["extended"])
        cls._tables(layout["inputs"], layout["outputs"])
        cls.description = str(layout["description"])

    @classmethod
    def _tables(cls, inputs: Any, outputs: Any) -> None:
        """The port table and what the build and the buffers take from it."""
        signals = _PLANT.signals
        cls.PORTS = (*signals.io_ports(inputs, outputs),
                     *_scene_mod.run_ports(cls.SCENE, cls.MODEL),
                     *(port for port, _s, _k in PARAMETERS))
        cls.REAL_INPUTS = tuple(p.name for p in cls.PORTS if p.causality == "input")
        cls.REAL_OUTPUTS = tuple(p.name for p in cls.PORTS if p.causality == "output")
        #: units and output dependencies (none: outputs change only in doStep), for the build
        cls.VARIABLE_UNITS = support.units_of(cls.PORTS)
        cls.DIRECT_FEEDTHROUGH = dict.fromkeys(cls.REAL_OUTPUTS, ())

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.default_experiment = support.DefaultExperiment(start_time=0.0, stop_time=30.0,
                                                            step_size=1e-3)
        #: every parameter's value by name (the run parameters, then the scalar ones)
        self._values: dict[str, Any] = {}

        self._mode = "instantiated"  # -> "initialization" -> "step"
        self._start_time = 0.0
        self._sim: Any = None
        self._out_index: np.ndarray = np.zeros(0, dtype=np.int64)
        self._in_index: np.ndarray = np.zeros(0, dtype=np.int64)
        self._u: np.ndarray = np.zeros(0)  # the model's input vector (undeclared entries 0)
        self._all_inputs = True  # the declared inputs are the model's, in its order
        self._built_key: tuple[Any, ...] | None = None
        self._init_error: str | None = None  # invalid parameters: every doStep refused
        self._halted: str | None = None  # divergence, until a state is restored
        self._step: Any = None  # the compiled step of self._step_sim (None: none)
        self._step_sim: Any = None
        self._scenes = scenes_folder(self.resources)
        self.register_ports(self.PORTS, self._values)
        if _IMPORT_WARNING:
            self.log(f"{self.instance_name}: {_IMPORT_WARNING}",
                     status=support.Fmi2Status.warning)

    @property
    def scene(self) -> str:
        """The ``scene`` parameter."""
        return self._values["scene"]

    @property
    def model(self) -> str:
        """The ``model`` parameter."""
        return self._values["model"]

    @property
    def max_internal_step(self) -> float:
        """The ``max_internal_step`` parameter [s]."""
        return self._values["max_internal_step"]

    # ------------------------------------------------------------------ helpers
    def _key(self) -> tuple[Any, ...]:
        return tuple(self._values.values())

    def _set_through_fmi(self) -> list[tuple[str, str, str, Any]]:
        """(FMU name, section, field, value) of every parameter that differs from its start.

        Those override the scene (see the module docstring); a value equal to its start never
        does, so an importer writing every start value changes nothing.
        """
        changed = []
        for port, section, key in PARAMETERS:
            value, start = self._values[port.name], port.start
            if value == start and isinstance(value, bool) == isinstance(start, bool):
                continue  # at its start value (NaN never is): the scene decides
            changed.append((port.name, section, key, value))
        return changed

    def _checked_overrides(self, scene: Any) -> dict[str, Any]:
        """Nested scene overrides of the parameters set through FMI, each checked alone.

        Every section's changed fields are applied together to the scene's values of that
        section: an out-of-range value raises ValueError naming the FMU variable and its
        allowed range, never the scene file.
        """
        over: dict[str, Any] = {}
        for _name, section, field_, value in self._set_through_fmi():
            if section:
                over.setdefault(section, {})[field_] = value
            else:
                over[field_] = value
        for section, fields_ in over.items():
            try:
                if isinstance(fields_, dict):
                    dataclasses.replace(getattr(scene.plant, section), **fields_)
                else:
                    dataclasses.replace(scene.plant, **{section: fields_})
            except ValueError as exc:
                raise ValueError(f"FMU parameter {exc}") from None
        if self.model not in MODEL_CHOICES:
            raise ValueError(f"FMU parameter model = {self.model!r} is not allowed: one of "
                             f"{', '.join(MODEL_CHOICES)}")
        if self.model != "auto":
            over["model"] = self.model
        return over

    def _make_simulator(self) -> Any:
        """Scene -> PlantParams -> DrillstringModel -> PlantSimulator (ValueError if invalid)."""
        step = self.max_internal_step
        if not (isinstance(step, float) and math.isfinite(step) and step >= 0.0):
            raise ValueError(f"FMU parameter max_internal_step = {step!r} is out of range: "
                             f"allowed [0, inf) s (0 = the model's stable step)")
        base = _scene_mod.load_scene(self.scene, folder=self._scenes)  # the file's own errors
        overrides = self._checked_overrides(base)
        try:
            scene = _scene_mod.load_scene(self.scene, folder=self._scenes, overrides=overrides)
        except ValueError as exc:  # a combination: the scene's values with the FMU's
            names = ", ".join(f"{n} = {v!r}" for n, _s, _f, v in self._set_through_fmi())
            raise ValueError(f"the FMU parameters set ({names or 'model = ' + repr(self.model)})"
                             f" do not fit scene {self.scene!r}: {exc}") from None
        model = _model_mod.DrillstringModel(scene.plant, scene.model,
                                            extended_outputs=True if self.EXTENDED else None)
        missing = [n for n in self.REAL_OUTPUTS if n not in model.output_names]
        fix = (f"build the plant FMU for that scene (drillcosim build --scene {self.scene}) or "
               f"use the scene this FMU was built for ({self.SCENE}, model = {self.MODEL!r})")
        if missing:
            raise ValueError(
                f"scene {self.scene!r} with model = {self.model!r} builds the {model.kind} model "
                f"with contact bodies {list(model.contact_bodies)} and {model.n_sites} actuator "
                f"sites; it lacks the declared outputs {', '.join(missing)}: {fix}")
        acting, declared = model.acting_inputs, self.REAL_INPUTS
        if set(declared) - set(model.input_names) or set(acting) - set(declared):
            raise ValueError(
                f"scene {self.scene!r} with model = {self.model!r} builds the {model.kind} model "
                f"whose inputs are [{', '.join(acting)}]; this FMU's inputs are "
                f"[{', '.join(declared)}]: {fix}")
        sim = _with_spectral_memo(lambda: _sim_mod.PlantSimulator(
            model, None if step == 0.0 else step))
        sim.time = float(self._start_time)
        return _Built(sim, np.array([model.output_names.index(n) for n in self.REAL_OUTPUTS]),
                      np.array([model.input_names.index(n) for n in declared], dtype=np.int64),
                      np.zeros(model.n_inputs), list(declared) == list(model.input_names))

    def _adopt(self, built: _Built | None, key: tuple[Any, ...] | None) -> None:
        """Take a built simulator (None: none) as the instance's, for the parameters ``key``."""
        self._built_key = key
        self._init_error = None
        self._sim = None
        if built is not None:
            self._sim = built.sim
            self._out_index, self._in_index = built.out_index, built.in_index
            self._u, self._all_inputs = built.u, built.all_inputs

    def _build(self) -> None:
        """(Re)build the simulator when the parameters changed; log a failure once."""
        key = self._key()
        if key == self._built_key:
            return
        self._adopt(None, key)
        try:
            self._adopt(self._make_simulator(), key)
        except ValueError as exc:  # SceneError is a ValueError
            self._init_error = f"invalid parameter: {exc}"
        except Exception:  # noqa: BLE001 - a bug: keep its traceback for every later doStep
            self._init_error = f"internal error while building the model:\n{traceback.format_exc()}"
        if self._init_error is not None:
            self._error(f"initialization failed: {self._init_error}; every doStep will be "
                        f"rejected (correct the parameters, reset or re-instantiate)")
        else:
            self._write_outputs()

    def _write_outputs(self) -> None:
        step = self._compiled()
        if step is not None:
            step.write_outputs()
        else:
            self._sim.outputs().take(self._out_index, out=self.outputs)

    # ---------------------------------------------------------------- FMI calls
    def setup_experiment(self, start_time: float, stop_time: float | None = None,
                         tolerance: float | None = None) -> None:
        self._start_time = float(start_time)

    def enter_initialization_mode(self) -> None:
        self._mode = "initialization"

    def exit_initialization_mode(self) -> None:
        fresh = self._key() != self._built_key
        self._build()  # a fresh failure is logged as fmi2Error; see "Error handling"
        if self._init_error is None:
            self._mode = "step"
        elif not fresh:  # the same parameters again: the same failure
            self._error(f"initialization failed: {self._init_error}")

    def do_step(self, current_time: float, step_size: float) -> None:
        t, h = current_time, step_size
        if self._init_error is not None or self._sim is None:
            return self._error(f"step rejected: {self._init_error}")
        if self._halted is not None:
            return self._error(f"step rejected at t = {t!r} s: the simulation diverged earlier "
                               f"({self._halted}); restore an FMU state saved before "
                               f"(fmi2SetFMUstate) or reset", support.Fmi2Status.discard)
        sim = self._sim
        if self._all_inputs:  # the default build: no copy per step
            sim.set_inputs(self.inputs)
        else:
            self._u.put(self._in_index, self.inputs)
            sim.set_inputs(self._u)
        return self._outcome(sim.do_step(t, h), t, h)

    def _outcome(self, result: Any, t: float, h: float) -> None:
        """Outputs of a successful step; the status and message of a failed one."""
        if not result.ok:
            if not result.quantity:  # refused before integrating: state unchanged
                return self._error(result.message)
            self._halted = (f"{result.message} (time {result.time!r} s, quantity "
                            f"{result.quantity}, value {result.value!r})")
            return self._error(f"doStep(t = {t!r} s, h = {h!r} s) discarded: {self._halted}",
                               support.Fmi2Status.discard)
        self._write_outputs()
        return None

    # ------------------------------------------------------------ compiled step
    def _fmi2_compiled_step(self) -> tuple[int, int] | None:
        """The simulator's compiled step for the wrapper (``plant.compiled_step``), or None:
        no valid model, diverged (every later doStep is discarded in Python), or none for the
        method or switched off (``DRILLCOSIM_COMPILED_STEP=0``)."""
        if self._init_error is not None or self._halted is not None:
            return None
        step = self._compiled()
        if step is None:
            return None
        step.refresh()
        return step.function, step.context

    def _compiled(self) -> Any:
        """The compiled step of the current simulator (made at its first use), or None."""
        sim = self._sim
        if sim is None:
            return None
        if self._step_sim is not sim:
            self._step_sim = sim
            self._step = None
            if _compiled_entries():
                self._step = sim.compiled_step(self.inputs, self._in_index, self.outputs,
                                               self._out_index)
        return self._step

    def _fmi2_compiled_step_failed(self, code: int, t: float, h: float) -> None:
        """Status and message of a compiled step that returned ``code`` (as :meth:`do_step`)."""
        return self._outcome(self._step.finish(code, t, h), t, h)

    # ----------------------------------------------------------------- access
    def _fixed_parameters_locked(self) -> bool:
        return self._mode == "step"

    def _accessible(self, vr: int, kind: type, call: str) -> bool:
        ok = super()._accessible(vr, kind, call)
        if ok and (call.startswith("get") and self._mode == "initialization"
                   and self.vars[vr].causality == support.Fmi2Causality.output):
            self._build()  # initial unknowns: computed from the parameters set so far
        return ok

    # ------------------------------------------------------------- FMU state
    def _internal_state(self) -> dict[str, Any]:
        sim = None
        if self._sim is not None:
            t, y, u = self._sim.get_state()
            sim = [float(t), y.tolist(), u.tolist()]
        return {"sim": sim, "halted": self._halted, "start_time": self._start_time}

    def _restore_internal(self, internal: dict[str, Any]) -> str | None:
        """The simulator of the state's parameters (built first if they differ from the
        instance's: refused as at initialization if they are invalid) and its time, state vector
        and held inputs, checked against that model; applied only when all fit."""
        sim, halted = internal.get("sim"), internal.get("halted")
        start_time = internal.get("start_time")
        if set(internal) != {"sim", "halted", "start_time"} or not (
                halted is None or isinstance(halted, str)):
            return f"not a state of this FMU (internal part {sorted(internal)})"
        problem = support.state.number_problem("start_time", start_time)
        if problem is None and sim is None and self._mode == "step":
            problem = "a state of a running plant without its simulator state"
        if problem is None and sim is not None:
            problem = _sim_problem(sim, finite=halted is None)
        if problem is not None:
            return problem
        key, built = self._key(), None
        if sim is not None and (key != self._built_key or self._sim is None):
            try:
                built = self._make_simulator()
            except ValueError as exc:
                return f"invalid parameter: {exc}"
        if sim is not None:
            target = built.sim if built is not None else self._sim
            t, y, u = sim
            if (len(y), len(u)) != (target.y.size, target.u.size):
                params = ", ".join(f"{n} = {v!r}" for n, _s, _f, v in self._set_through_fmi())
                return (f"its simulator state has {len(y)} values and {len(u)} inputs; the "
                        f"{target.model.kind} model of its parameters (scene {self.scene!r}"
                        f"{', ' if params else ''}{params}) has {target.y.size} and "
                        f"{target.u.size}")
        # every check passed: apply
        if built is not None:
            self._adopt(built, key)
        elif sim is None:
            self._adopt(None, None)  # as before the first build: built again when needed
        if sim is not None:
            self._sim.set_state((float(t), np.array(y, dtype=float), np.array(u, dtype=float)))
        self._halted, self._start_time = halted, float(start_time)
        return None


class _Built(NamedTuple):
    """A simulator made for the instance's parameters, with the indexes of the FMU's inputs and
    outputs in the model's vectors (:meth:`DrillstringPlant._make_simulator`)."""

    sim: Any
    out_index: np.ndarray
    in_index: np.ndarray
    u: np.ndarray
    all_inputs: bool


def _sim_problem(sim: Any, finite: bool) -> str | None:
    """Why ``sim`` is not [time, state vector, inputs] of numbers (finite ones unless the state
    is of a diverged, halted instance), or None."""
    if not (isinstance(sim, list) and len(sim) == 3 and isinstance(sim[1], list)
            and isinstance(sim[2], list)):
        return "its simulator state is not [time, state vector, inputs]"
    return (support.state.numbers_problem("its state vector", sim[1], finite)
            or support.state.numbers_problem("its held inputs", sim[2], finite)
            or support.state.number_problem("its time", sim[0]))


DrillstringPlant._tables(_INPUT_ROWS, _OUTPUT_ROWS)
