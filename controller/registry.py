"""The registered controller laws: one line per law (``controller/law.py`` says what a law
module holds).

Everything that serves a law finds it here by its ``kind``: the scene tables
(``[controller] kind = "..."``), the in-process slaves, the FMU build, the compiled steps and
the docs.
"""

from __future__ import annotations

from importlib import import_module

from .law import Law

__all__ = ["LAWS", "TABLES", "default_kind", "kinds", "law_named"]

#: The laws as (module of this package, class), one line each; the default law of each scene
#: table first.
REGISTERED: tuple[tuple[str, str], ...] = (
    ("strain_feedback", "StrainController"),
    ("top_drive", "TopDriveController"),
    ("state_space", "StateSpaceController"),
    ("pd_strain", "PDStrainController"),
    ("ztorque", "ZTorqueController"),
)
#: The law classes, in :data:`REGISTERED` order.
LAWS: tuple[type[Law], ...] = tuple(getattr(import_module(f".{module}", __package__), name)
                                    for module, name in REGISTERED)

#: The scene tables (= system instances) the laws fill, in the system's order.
TABLES: tuple[str, ...] = tuple(dict.fromkeys(law.TABLE for law in LAWS))


def kinds(table: str) -> tuple[str, ...]:
    """The ``kind`` values of scene table ``table``, its default first."""
    return tuple(law.KIND for law in LAWS if law.TABLE == table)


def default_kind(table: str) -> str:
    """The ``kind`` a scene table has when it names none."""
    return kinds(table)[0]


def law_named(kind: str) -> type[Law]:
    """The law of ``kind`` (``KeyError`` if none is registered)."""
    for law in LAWS:
        if law.KIND == kind:
            return law
    raise KeyError(kind)
