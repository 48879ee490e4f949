"""Which files of the third-party distributions a self-contained FMU ships.

The rule (:func:`select`): of a distribution whose top-level packages appear in
``imported_packages.txt`` (the packages the slaves import, traced by
``tests/support/trace_imports.py``), the files of the listed packages' own folders, its
``<name>.libs`` folder (the shared libraries its extension modules link) and its
``.dist-info`` (licences); a distribution none of whose packages is listed is shipped whole.
Compiled caches (``__pycache__``) are never shipped: the runtime compiles its own. A folder is
shipped whole, not module by module, so a module the traced runs did not import but a sibling
imports on another path (an error path, another integrator) is there.
"""

from __future__ import annotations

import importlib.metadata as metadata
import re
from collections.abc import Iterable, Sequence
from pathlib import Path, PurePosixPath

__all__ = ["IMPORTED", "distributions", "imported_packages", "select"]

IMPORTED = Path(__file__).with_name("imported_packages.txt")


def imported_packages(path: Path = IMPORTED) -> frozenset[str]:
    """The dotted package names of ``imported_packages.txt``."""
    lines = (line.split("#", 1)[0].strip() for line in path.read_text().splitlines())
    return frozenset(line for line in lines if line)


def _requirement_name(spec: str) -> str | None:
    """The distribution a ``Requires-Dist`` line names, None if only an extra needs it."""
    if re.search(r"extra\s*==", spec):
        return None
    match = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", spec)
    return match.group(1) if match else None


def distributions(modules: Sequence[str]) -> list[metadata.Distribution]:
    """The installed distributions that provide ``modules`` (import names) and every
    distribution they require (not their extras), in a stable order.

    Raises
    ------
    ModuleNotFoundError
        A module no installed distribution provides.
    """
    providers = metadata.packages_distributions()
    todo: list[str] = []
    for module in modules:
        names = providers.get(module.split(".")[0])
        if not names:
            raise ModuleNotFoundError(f"no installed distribution provides {module!r}: "
                                      f"install it into the building Python")
        todo += names
    found: dict[str, metadata.Distribution] = {}
    while todo:
        name = todo.pop(0)
        key = re.sub(r"[-_.]+", "-", name).lower()
        if key in found:
            continue
        dist = metadata.distribution(name)
        found[key] = dist
        todo += [n for n in map(_requirement_name, dist.requires or []) if n]
    return [found[k] for k in sorted(found)]


def select(files: Iterable[str], packages: frozenset[str]) -> list[str]:
    """The files (relative to site-packages, ``/``-separated) of one distribution to ship.

    Parameters
    ----------
    files : iterable of str
        The distribution's files (its RECORD).
    packages : frozenset of str
        Dotted package names imported (:func:`imported_packages`).
    """
    files = [PurePosixPath(f) for f in files]
    tops = {f.parts[0] for f in files if len(f.parts) > 1 and not f.parts[0].endswith(
        (".dist-info", ".libs", ".data"))}
    pruned = any(p.split(".")[0] in tops for p in packages)
    chosen = []
    for f in files:
        if "__pycache__" in f.parts or f.parts[0] == ".." or f.suffix == ".pyc":
            continue
        head = f.parts[0]
        keep = (not pruned or head.endswith((".dist-info", ".libs"))
                or ".".join(f.parts[:-1]) in packages
                or (len(f.parts) == 1 and f.stem in packages))
        if keep:
            chosen.append(f.as_posix())
    return chosen
