"""Which files of the third-party distributions a self-contained FMU ships.

The rule (:func:`select`): of a distribution whose top-level packages appear in
``imported_packages.txt`` (the packages the slaves import, traced by
``tests/support/trace_imports.py``), the files of the listed packages' own folders, its
``<name>.libs`` folder (the shared libraries its extension modules link) and its
``.dist-info`` (licences); a distribution none of whose packages is listed is shipped whole.
Compiled caches (``__pycache__``) are never shipped: the runtime compiles its own. A folder is
shipped whole, not module by module, so a module the traced runs did not import but a sibling
imports on another path (an error path, another integrator) is there. And the folders of the
modules reached from the traced packages' ``__init__.py`` through module-level imports (read
with ``ast``) are added: a release other than the traced one that moved code into a new
subpackage (scipy 1.18's ``scipy._external``) still gets it.
"""

from __future__ import annotations

import ast
import importlib.metadata as metadata
import re
from collections.abc import Callable, Iterable, Sequence
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


def _resolve(module: str, level: int, package: str) -> str:
    """The absolute name of ``from <level dots><module> import``, in ``package``."""
    if not level:
        return module
    parts = package.split(".")
    parts = parts[:len(parts) - level + 1] if level > 1 else parts
    return ".".join(parts + ([module] if module else []))


_FROM = re.compile(r"^from\s+(\.*)([\w.]*)\s+import\s+(\([^)]*\)|[^\n]*)", re.M)
_IMPORT = re.compile(r"^import\s+([^\n]+)", re.M)


def _imported(source: bytes, package: str) -> set[str]:
    """Dotted names a module imports at its top level (relative ones resolved in
    ``package``, the module's own package). Code of a newer Python than the building one
    (a syntax ``ast`` rejects) is read line by line instead: its unindented imports."""
    names = set()
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        text = source.decode("utf-8", "replace")
        for dots, module, what in _FROM.findall(text):
            base = _resolve(module, len(dots), package)
            names.add(base)
            for item in re.sub(r"#[^\n]*", "", what).strip("() \n").split(","):
                alias = item.split(" as ")[0].strip()
                if alias.isidentifier():
                    names.add(f"{base}.{alias}")
        for line in _IMPORT.findall(text):
            names.update(part.split(" as ")[0].strip() for part in line.split(","))
        return names
    for node in tree.body:
        for sub in ast.walk(node) if isinstance(node, (ast.If, ast.Try)) else [node]:
            if isinstance(sub, ast.Import):
                names.update(alias.name for alias in sub.names)
            elif isinstance(sub, ast.ImportFrom):
                base = _resolve(sub.module or "", sub.level, package)
                names.add(base)
                names.update(f"{base}.{alias.name}" for alias in sub.names)
    return names


def _close(files: list[PurePosixPath], folders: set[str], tops: set[str],
           chosen_folders: set[str], read: Callable[[str], bytes]) -> None:
    """Add to ``chosen_folders`` the folders of the modules reached from their packages'
    ``__init__`` through module-level imports (a module graph, as modulegraph builds)."""
    modules = {}
    for f in files:
        if f.suffix == ".py":
            name = ".".join(f.parts[:-1] if f.name == "__init__.py" else (*f.parts[:-1], f.stem))
            modules[name] = f
    todo = sorted(m for m in chosen_folders if m in modules)
    seen = set(todo)
    while todo:
        module = todo.pop()
        path = modules[module]
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for name in _imported(read(path.as_posix()), package):
            while name and name not in modules:
                name = name.rpartition(".")[0]  # an attribute: its module
            if not name or name.split(".")[0] not in tops:
                continue
            parts = name.split(".")
            for k in range(1, len(parts) + 1):  # the module and its packages
                dotted = ".".join(parts[:k])
                if dotted in modules and dotted not in seen:
                    seen.add(dotted)
                    todo.append(dotted)
                folder = dotted if dotted in folders else ".".join(parts[:k - 1])
                if folder:
                    chosen_folders.add(folder)


def select(files: Iterable[str], packages: frozenset[str],
           read: Callable[[str], bytes] | None = None) -> list[str]:
    """The files (relative to site-packages, ``/``-separated) of one distribution to ship.

    Parameters
    ----------
    files : iterable of str
        The distribution's files (its RECORD, or a wheel's members).
    packages : frozenset of str
        Dotted package names imported (:func:`imported_packages`).
    read : callable, optional
        ``read(path) -> bytes`` of a file: the chosen folders are then closed over the
        module-level imports of their modules (see the module docstring).
    """
    files = [PurePosixPath(f) for f in files]
    folders = {".".join(f.parts[:-1]) for f in files if len(f.parts) > 1}
    tops = {f.parts[0] for f in files if len(f.parts) > 1 and not f.parts[0].endswith(
        (".dist-info", ".libs", ".data"))}
    chosen_folders = {p for p in packages if p in folders or p.split(".")[0] in tops}
    pruned = bool(chosen_folders)
    if read is not None:
        _close(files, folders, tops, chosen_folders, read)
    chosen = []
    for f in files:
        if "__pycache__" in f.parts or f.parts[0] == ".." or f.suffix == ".pyc":
            continue
        head = f.parts[0]
        keep = (not pruned or head.endswith((".dist-info", ".libs"))
                or ".".join(f.parts[:-1]) in chosen_folders
                or (len(f.parts) == 1 and f.stem in packages))
        if keep:
            chosen.append(f.as_posix())
    return chosen
