"""pythonfmu adapter: a generic discrete state-space controller as an FMI 2.0 co-simulation FMU.

The law (``controller/state_space.py``, vendored as ``_dcs_controller_0_1_0``) at its sample
period Ts::

    u[k] = clip(C x[k] + D y[k], lower, upper),    x[k+1] = A x[k] + B y[k]

``fmi2DoStep(t, h)`` runs ``h / Ts`` samples with the inputs held (``h`` an integer multiple of
Ts) and leaves ``u`` of the last one in the outputs: the output after a step comes from the
inputs set before it (no direct feedthrough within a communication point).

Where the numbers come from
---------------------------
The interface (input and output names, units, descriptions, the start of the limits, the number
of states, Ts) is the class attribute ``LAYOUT``; the matrices are the resource file
``resources/state_space.json`` (``controller.state_space`` JSON format, exact floats), read at
instantiation. The default build (``StateSpaceController.fmu``) carries the paper's P law
for two sites (no state, ``D = 1e9 I``, Ts = 0.25 ms: ``fmu_src/state_space_default.json``);
a variant built for a scene (``fmu_src/build.py``, "Variants") carries the scene's controller.
A user can put any linear controller in: replace the JSON (same names, units, sizes) or build a
variant.

Interface
---------
inputs  (Real, continuous, start 0): ``LAYOUT["inputs"]`` (default ``strain<s>_<C|E>``, unit 1)
outputs (Real, continuous, initial exact, start 0): ``LAYOUT["outputs"]`` (default
    ``actuator<s>_force_<C|E>``, N)
parameters: ``lower_limit_<output>`` / ``upper_limit_<output>`` (tunable, the output's unit):
    saturation; "no limit" is -/+1e300.

Compiled step
-------------
Where numba is loaded in the process (by the plant FMU, in the main job) the law's compiled
step (``controller.compiled.state_space_step``, a numba ``cfunc`` cached beside the stable copy
of the vendored package, ``slave_support.vendored``) runs every doStep without entering Python
(``slave_support.LawSlave``); elsewhere, or with ``DRILLCOSIM_COMPILED_STEP=0``, doStep is the
numpy reference (the same law; the two agree to rounding).

Errors (the status protocol of ``fmu_src/slave_support``)
---------------------------------------------------------
* a resource file that is missing, unreadable, or not a valid controller of this FMU's interface
  (shapes, non-finite entries, names, units, Ts that do not match ``LAYOUT``): fmi2Instantiate
  fails (returns NULL) with that one line logged (status Error);
* limits with lower > upper: fmi2Error naming them (at initialization or the next doStep);
* a step that is not a multiple of Ts, a non-finite input or time: fmi2Error from that doStep,
  state unchanged.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

from _dcs_pythonfmu_0_7_0 import (
    DefaultExperiment,
    Fmi2Causality,
    Fmi2Initial,
    Fmi2Variability,
    Real,
)
from _dcs_pythonfmu_0_7_0.enums import Fmi2Status
from _dcs_slave_support_0_1_0 import LawSlave
from _dcs_slave_support_0_1_0.vendored import import_vendored

#: Name under which the build vendors ``controller/`` into this FMU's resources.
VENDORED_CONTROLLER = "_dcs_controller_0_1_0"
# from a stable copy where numba can compile the law's step (its cache needs a fixed path)
_CONTROLLER, _IMPORT_WARNING = import_vendored(VENDORED_CONTROLLER, __file__, only_with="numba")
from _dcs_controller_0_1_0.state_space import (  # noqa: E402 - imported above from its copy
    StateSpaceController as StateSpaceLaw,
)
from _dcs_controller_0_1_0.state_space import StateSpaceParams, load_state_space  # noqa: E402

#: The resource file of the matrices.
RESOURCE = "state_space.json"
#: The FMU's "no limit" (a start value every XML reader parses; no force comes near it).
NO_LIMIT = 1e300

_CHANNELS = [(s, a) for s in (1, 2) for a in ("C", "E")]
_PAIR = {"C": "D", "E": "F"}
#: The default build's interface: the paper's two sites (``fmu_src/state_space_default.json``).
DEFAULT_LAYOUT: dict[str, Any] = {
    "inputs": [[f"strain{s}_{a}", "1", f"Surface strain at gauge {a}, site {s}; tensile > 0"]
               for s, a in _CHANNELS],
    "outputs": [[f"actuator{s}_force_{a}", "N",
                 f"Actuator force at site {s}, axis {a}; > 0 = compressive at "
                 f"{_PAIR[a]} / tensile at {a}"] for s, a in _CHANNELS],
    "lower": [None] * 4, "upper": [None] * 4, "n_states": 0, "sample_period": 2.5e-4,
    "description": ("Generic discrete state-space controller u = clip(C x + D y), x+ = A x + B y "
                    "(matrices in resources/state_space.json); this build: the paper's P law, "
                    "2 sites x gauges C/E, D = 1e9 N/strain, no state, Ts = 0.25 ms"),
}


def _limit_names(outputs: list[str]) -> tuple[str, ...]:
    return tuple(f"{side}_limit_{o}" for o in outputs for side in ("lower", "upper"))


class StateSpaceController(LawSlave):
    """FMI 2.0 co-simulation adapter of :class:`controller.state_space.StateSpaceController`."""

    author = "drillcosim"
    version = "0.1.0"
    LAYOUT: ClassVar[dict[str, Any]] = DEFAULT_LAYOUT
    REAL_INPUTS = tuple(r[0] for r in DEFAULT_LAYOUT["inputs"])
    REAL_OUTPUTS = tuple(r[0] for r in DEFAULT_LAYOUT["outputs"])
    TUNABLE = _limit_names(list(REAL_OUTPUTS))
    FIXED = ()
    LAW_PACKAGE = _CONTROLLER
    VARIABLE_UNITS: ClassVar[dict[str, str]] = {}
    DIRECT_FEEDTHROUGH: ClassVar[dict[str, tuple[str, ...]]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A variant: the class tables from its ``LAYOUT``."""
        super().__init_subclass__(**kwargs)
        if "LAYOUT" in cls.__dict__:
            cls._tables()

    @classmethod
    def _tables(cls) -> None:
        lay = cls.LAYOUT
        for key in ("inputs", "outputs", "lower", "upper", "n_states", "sample_period",
                    "description"):
            if key not in lay:
                raise ValueError(f"{cls.__name__}: LAYOUT has no {key!r}")
        cls.REAL_INPUTS = tuple(r[0] for r in lay["inputs"])
        cls.REAL_OUTPUTS = tuple(r[0] for r in lay["outputs"])
        cls.TUNABLE = _limit_names(list(cls.REAL_OUTPUTS))
        units = {r[0]: r[1] for r in (*lay["inputs"], *lay["outputs"])}
        for o, unit in ((r[0], r[1]) for r in lay["outputs"]):
            units[f"lower_limit_{o}"] = unit
            units[f"upper_limit_{o}"] = unit
        cls.VARIABLE_UNITS = units
        cls.DIRECT_FEEDTHROUGH = dict.fromkeys(cls.REAL_OUTPUTS, ())
        cls.description = str(lay["description"])

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=30.0,
                                                    step_size=float(self.LAYOUT["sample_period"]))
        self._base: StateSpaceParams | None = None
        try:
            self._base = self._load()
        except ValueError as exc:
            # the wrapper takes this status from the construction: fmi2Instantiate fails
            self._error(f"fmi2Instantiate: {exc}")
        else:
            self._law = StateSpaceLaw(self._base)
        lay = self.LAYOUT
        for name, _unit, doc in lay["inputs"]:
            self.register_real_io(Real(name, causality=Fmi2Causality.input,
                                       variability=Fmi2Variability.continuous, description=doc))
        for name, _unit, doc in lay["outputs"]:
            self.register_real_io(Real(
                name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                initial=Fmi2Initial.exact, description=f"{doc} (after the step: from the "
                "inputs set before it)"))
        for (name, _u, _d), lo, hi in zip(lay["outputs"], lay["lower"], lay["upper"]):
            for side, start in (("lower", lo), ("upper", hi)):
                self._register_limit(f"{side}_limit_{name}", side, name,
                                     (-NO_LIMIT if side == "lower" else NO_LIMIT)
                                     if start is None else float(start))
        if _IMPORT_WARNING:
            self.log(f"{self.instance_name}: {_IMPORT_WARNING}", status=Fmi2Status.warning)

    def _register_limit(self, name: str, side: str, output: str, start: float) -> None:
        self.param_values[name] = start

        def getter() -> float:
            return self.param_values[name]

        def setter(value: float) -> None:
            self.param_values[name] = value

        self.register_variable(Real(
            name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable,
            getter=getter, setter=setter,
            description=f"Saturation: {side} limit of {output} (+-{NO_LIMIT!r} = none)"),
            nested=False)

    # ------------------------------------------------------------------ loading
    def _load(self) -> StateSpaceParams:
        """The resource file, checked against ``LAYOUT`` (ValueError: one line)."""
        if not self.resources:
            raise ValueError(f"no resources folder: {RESOURCE} cannot be found")
        path = Path(self.resources) / RESOURCE
        if not path.is_file():
            raise ValueError(f"resources/{RESOURCE} is missing: the FMU has no matrices")
        params = load_state_space(path)
        lay = self.LAYOUT
        want = {"inputs": [tuple(r[:2]) for r in lay["inputs"]],
                "outputs": [tuple(r[:2]) for r in lay["outputs"]],
                "n_states": lay["n_states"], "sample_period": float(lay["sample_period"])}
        have = {"inputs": [(s.name, s.unit) for s in params.inputs],
                "outputs": [(s.name, s.unit) for s in params.outputs],
                "n_states": params.n_states, "sample_period": params.sample_period}
        for key, value in want.items():
            if have[key] != value:
                raise ValueError(f"resources/{RESOURCE} does not fit this FMU: {key} "
                                 f"{have[key]!r}; the FMU declares {value!r}")
        return params

    # ------------------------------------------------------------------ the law
    def _params_from_variables(self) -> StateSpaceParams:
        lower = [self.param_values[f"lower_limit_{o}"] for o in self.REAL_OUTPUTS]
        upper = [self.param_values[f"upper_limit_{o}"] for o in self.REAL_OUTPUTS]
        bad = [o for o, lo, hi in zip(self.REAL_OUTPUTS, lower, upper) if not lo <= hi]
        if bad:
            raise ValueError(f"lower_limit > upper_limit (or NaN) for {', '.join(bad)}; "
                             "allowed: lower <= upper")
        return self._base.with_limits(lower, upper)

    def _make_law(self, params: StateSpaceParams) -> StateSpaceLaw:
        self._law.params = params   # other limits only: the state is kept (reset: zero)
        return self._law

    def _step_law(self, t: float, h: float) -> None:
        self.outputs[:] = self._law.step(t, h, self.inputs)


StateSpaceController._tables()
