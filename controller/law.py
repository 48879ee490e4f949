"""The plug-in contract of a controller law.

A law is one module in ``controller/`` plus one line in ``controller/registry.py``. The module
holds:

1. **Its parameters**: a frozen dataclass deriving from :class:`Settings` whose fields are
   declared with :func:`setting` (default, unit, description, range, tunable or fixed,
   choices). :class:`Settings` validates them in ``__post_init__`` (one ``ValueError`` naming
   the field, the value and what is allowed); the fields are the keys of the law's scene table.
2. **Its law**: a subclass of :class:`Law` with the class attributes ``KIND`` (the scene's
   ``kind``), ``TABLE`` (the scene table and system instance it fills: ``"controller"`` or
   ``"top_drive_controller"``), ``FMU`` (its FMU's model identifier), ``DESCRIPTION`` and
   ``PARAMS``, and the methods :meth:`Law.io_ports` (its inputs and outputs for a layout),
   ``reset``, ``get_state`` / ``set_state``, :meth:`Law.initial_outputs` and :meth:`Law.advance`
   (one step: the outputs at ``t + h`` from the inputs held over the step; ``ValueError`` for a
   step it refuses, state unchanged), and a settable ``params`` that keeps the state.
3. **Its port table**: :meth:`Law.ports` = the inputs and outputs, then one parameter per
   field of ``PARAMS`` (:meth:`Law.parameter_ports`, from the fields' metadata); a law whose
   FMU encodes a field otherwise (a matrix as entries) overrides :meth:`Law.parameter_ports`,
   :meth:`Law.encode` and :meth:`Law.decode`.
4. **Its compiled step** (optional): ``COMPILED = (core function name, dimensions of its
   arrays)``, a function of the module written in numba's nopython subset
   (``core(t, h, *arrays) -> code``, :data:`acceleration.OK` / ``FALLBACK`` / ``REFUSED``)
   that does what :meth:`Law.advance` does on the law's own arrays, and ``compiled_step``
   packing those arrays (:func:`acceleration.compiled_law`). ``controller/compiled.py`` makes
   the C entry point of every registered core; the module itself never imports numba.

From these the rest follows without further code: the scene table ``[controller] kind =
"..."`` (``cosim.scenario.config``), the in-process slave (``cosim.scenario.inprocess``), the
FMU (``fmu_src/law_fmu.py``, built by ``fmu_src/build.py`` from the registry), the start values
an FMU of the law gets, the scene schema and the interface docs.

A *layout* is what a law's interface depends on (a JSON-ready dict: the number of actuator
sites of a strain law; ``{}`` for a fixed interface): :meth:`Law.layout_for` gives it for a
scene, and an FMU built for another layout than :meth:`Law.default_layout` is a variant.

Only numpy and the standard library are imported (the package is vendored into the FMUs).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, Field, field, fields
from numbers import Real
from typing import Any, ClassVar

import numpy as np

from .ports import Port, parameter

__all__ = ["NO_LIMIT", "Law", "Settings", "setting"]

#: An FMU's stand-in for an infinite parameter value (a start value every XML reader parses).
NO_LIMIT = 1e30


def setting(default: Any, unit: str, doc: str, *, range: tuple[float, float] | None = None,
            open: tuple[bool, bool] = (False, False), fixed: bool = False,
            choices: tuple[str, ...] | None = None) -> Any:
    """A field of a law's parameters.

    Parameters
    ----------
    default : float, bool or str
        The default (also the FMU's start value).
    unit : str
        FMI unit name (``"N.m.s/rad"``; ``"1"`` dimensionless; ``""`` none).
    doc : str
        One line: what it is (the FMU variable's description, the scene schema's meaning).
    range : (float, float), optional
        Allowed ``[low, high]`` of a real (``inf`` allowed); checked by :class:`Settings`.
    open : (bool, bool)
        Whether ``low`` / ``high`` are excluded.
    fixed : bool
        The FMU parameter is fixed (set before initialization only); default tunable.
    choices : tuple of str, optional
        The allowed values of a string field (its FMU parameter is the Integer index).
    """
    return field(default=default, metadata={"setting": True, "unit": unit, "doc": doc,
                                            "range": range, "open": open, "fixed": fixed,
                                            "choices": choices})


def _check_real(name: str, value: object, low: float, high: float, *, low_open: bool = False,
                high_open: bool = False) -> float:
    """Return ``value`` as float if it lies in the interval, else raise ValueError.

    Parameters
    ----------
    name : str
        Parameter name, quoted in the error message.
    value : object
        Candidate value; must be a real number (``bool`` is rejected).
    low, high : float
        Interval bounds (may be infinite).
    low_open, high_open : bool
        Whether the respective bound is excluded.

    Returns
    -------
    float
        The validated value.

    Raises
    ------
    ValueError
        If the value is not a real number, is NaN or lies outside the interval.
        The message names the parameter, the value and the allowed range.
    """
    left = "<" if low_open else "<="
    right = "<" if high_open else "<="
    allowed = f"allowed: {low:g} {left} {name} {right} {high:g}"
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{name} = {value!r} is not a real number; {allowed}")
    x = float(value)
    if math.isnan(x):
        raise ValueError(f"{name} = nan is not allowed; {allowed}")
    too_low = x <= low if low_open else x < low
    too_high = x >= high if high_open else x > high
    if too_low or too_high:
        raise ValueError(f"{name} = {x!r} is out of range; {allowed}")
    return x


def _declared(f: Field) -> bool:
    """Whether ``f`` is a :func:`setting` (a field with only ``unit`` and ``doc`` metadata is a
    scene key the law's FMU encodes otherwise, e.g. a matrix)."""
    return f.metadata.get("setting", False) and f.default is not MISSING


class Settings:
    """Base of a law's parameters (a frozen dataclass of :func:`setting` fields): validated
    once, in ``__post_init__``; reals become ``float`` and booleans ``bool``."""

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            if _declared(f):
                object.__setattr__(self, f.name, self._checked(f, getattr(self, f.name)))

    @staticmethod
    def _checked(f: Field, value: Any) -> Any:
        meta = f.metadata
        if meta["choices"] is not None:
            if value not in meta["choices"]:
                allowed = ", ".join(map(repr, meta["choices"]))
                raise ValueError(f"{f.name} = {value!r} is not allowed; allowed: one of "
                                 f"{allowed}")
            return value
        if isinstance(f.default, bool):
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"{f.name} = {value!r} is not allowed; allowed: True or False")
            return bool(value)
        low, high = meta["range"] or (-math.inf, math.inf)
        low_open, high_open = meta["open"]
        return _check_real(f.name, value, low, high, low_open=low_open, high_open=high_open)


class Law:
    """Base of a controller law (see the module docstring for the contract).

    Subclasses set the class attributes below and implement ``__init__(params)`` (or
    :meth:`create` for a law that needs its layout), ``params`` (property, settable, keeps
    the state), ``reset``, ``get_state``, ``set_state``, :meth:`initial_outputs`,
    :meth:`advance` and :meth:`io_ports`.
    """

    #: The scene's ``kind`` of this law.
    KIND: ClassVar[str] = ""
    #: The scene table (= system instance) it fills.
    TABLE: ClassVar[str] = "controller"
    #: Model identifier of its FMU (a variant for another layout: ``<FMU>_<scene>``).
    FMU: ClassVar[str] = ""
    #: One line: the law (its FMU's description, the scene schema).
    DESCRIPTION: ClassVar[str] = ""
    #: Its parameters (a :class:`Settings` dataclass).
    PARAMS: ClassVar[type] = Settings
    #: Its compiled step: (name of the core function in the law's module, ndim of each array
    #: the core takes after ``t`` and ``h``); None: none.
    COMPILED: ClassVar[tuple[str, tuple[int, ...]] | None] = None
    #: A file its FMU carries in ``resources/`` and reads at instantiation (``""``: none; then
    #: ``load_resource(path, layout)`` reads it and ``decode`` gets what it returned), and the
    #: default FMU's copy of it (beside the law's module).
    RESOURCE: ClassVar[str] = ""
    DEFAULT_RESOURCE: ClassVar[str] = ""

    params: Any

    # ------------------------------------------------------------------ the interface
    @classmethod
    def layout_for(cls, params: Any, n_sites: int) -> dict[str, Any]:
        """The layout a scene with these parameters and ``n_sites`` actuator sites needs
        (``{}``: the law has one interface)."""
        return {}

    @classmethod
    def default_layout(cls) -> dict[str, Any]:
        """The layout of the law's default FMU (the default parameters, two sites)."""
        return cls.layout_for(cls.PARAMS(), 2)

    @classmethod
    def io_ports(cls, layout: Mapping[str, Any]) -> tuple[Port, ...]:
        """The inputs and outputs (in the order of the law's arrays) for ``layout``."""
        raise NotImplementedError

    @classmethod
    def parameter_ports(cls, layout: Mapping[str, Any]) -> tuple[Port, ...]:
        """One parameter per field of :attr:`PARAMS`, from the fields' metadata: a string
        field with choices is an Integer (the index of its value), a boolean a Boolean, a real
        a Real (an infinite default starts at :data:`NO_LIMIT`)."""
        out = []
        for f in fields(cls.PARAMS):
            if not _declared(f):
                continue
            meta = f.metadata
            if meta["choices"] is not None:
                doc = ", ".join(f"{i} = {c}" for i, c in enumerate(meta["choices"]))
                out.append(parameter(f.name, "", f"{meta['doc']} ({doc})",
                                     meta["choices"].index(f.default), tunable=False,
                                     range=(0, len(meta["choices"]) - 1), type="Integer"))
            elif isinstance(f.default, bool):
                out.append(parameter(f.name, "", meta["doc"], f.default,
                                     tunable=not meta["fixed"], type="Boolean"))
            else:
                out.append(parameter(f.name, meta["unit"], meta["doc"], _fmu_real(f.default),
                                     range=meta["range"], tunable=not meta["fixed"]))
        return tuple(out)

    @classmethod
    def ports(cls, layout: Mapping[str, Any] | None = None) -> tuple[Port, ...]:
        """The law's port table for ``layout`` (default: :meth:`default_layout`)."""
        layout = cls.default_layout() if layout is None else layout
        return (*cls.io_ports(layout), *cls.parameter_ports(layout))

    @classmethod
    def encode(cls, params: Any, layout: Mapping[str, Any]) -> dict[str, Any]:
        """``params`` as the values of the FMU's parameters (the inverse of :meth:`decode`)."""
        out = {}
        for f in fields(cls.PARAMS):
            if not _declared(f):
                continue
            value = getattr(params, f.name)
            choices = f.metadata["choices"]
            out[f.name] = (choices.index(value) if choices is not None
                           else value if isinstance(value, bool) else _fmu_real(value))
        return out

    @classmethod
    def decode(cls, values: Mapping[str, Any], layout: Mapping[str, Any], base: Any = None
               ) -> Any:
        """Validated parameters from the values of the FMU's parameters (``ValueError``
        naming a bad one); ``base``: what a law with a resource file read from it."""
        kwargs = {}
        for f in fields(cls.PARAMS):
            if not _declared(f):
                continue
            value = values[f.name]
            choices = f.metadata["choices"]
            low, high = f.metadata["range"] or (-math.inf, math.inf)
            if isinstance(value, float) and abs(value) >= NO_LIMIT and (
                    math.isinf(high) if value > 0 else math.isinf(low)):
                value = math.copysign(math.inf, value)  # the FMU's stand-in (:func:`_fmu_real`)
            if choices is not None:
                if isinstance(value, bool) or not isinstance(value, int) or not (
                        0 <= value < len(choices)):
                    allowed = ", ".join(f"{i} ({c})" for i, c in enumerate(choices))
                    raise ValueError(f"{f.name} = {value!r} is not allowed; allowed: {allowed}")
                value = choices[value]
            kwargs[f.name] = value
        return cls.PARAMS(**kwargs)

    @classmethod
    def create(cls, params: Any, layout: Mapping[str, Any]) -> Law:
        """A law of ``params`` for ``layout``."""
        return cls(params)  # type: ignore[call-arg]

    # ------------------------------------------------------------------ the law
    def initial_outputs(self) -> np.ndarray:  # pragma: no cover - each law its own
        """The outputs before the first step (after :meth:`reset`)."""
        raise NotImplementedError

    def advance(self, t: float, h: float, inputs: np.ndarray, outputs: np.ndarray) -> None:
        """One step over ``[t, t + h]`` with ``inputs`` held: write the outputs at ``t + h``
        into ``outputs`` (``ValueError`` for a refused step, state unchanged)."""
        raise NotImplementedError  # pragma: no cover

    def compiled_step(self, inputs: np.ndarray, outputs: np.ndarray) -> Any:
        """The law's compiled step on ``inputs`` / ``outputs`` (None: none)."""
        return None


def _fmu_real(value: float) -> float:
    """A real as an FMU Real: infinity as :data:`NO_LIMIT`."""
    return math.copysign(NO_LIMIT, value) if math.isinf(value) else float(value)

