"""Native images: the compiled steps' machine code, loaded without numba's compiler.

The compiled steps (``plant.compiled_step``, ``controller.compiled``) are numba ``@cfunc``
functions. Getting one from numba's cache costs the process numba's set-up at its first use
(~0.25 s of typing and lowering registries), whoever asks first; yet an FMU instance only
hands the C wrapper an address. So the first process that gets the cfuncs of a vendored package
from numba also writes their object code (exactly what numba cached) into a *native image*
beside the package's stable copy (:mod:`slave_support.vendored`). Later processes on the same
machine load the image with llvmlite's MCJIT (a few milliseconds) and never set numba up: the
step runs the very machine code numba made, so its results are the numba path's, bit for bit.

An image is used only where it was made for: the same package code (the stable copy's folder is
named by its content hash), the same numba, llvmlite and Python versions, and the same target as
numba keys its own cache by (triple, CPU name, CPU features). Anything else, an unreadable,
cut or damaged image, or a symbol missing from it, falls back to numba, which compiles or loads
as before and writes a new image. ``DRILLCOSIM_NATIVE_IMAGE=0`` switches images off, and so does
a numba release outside :data:`NUMBA_RELEASES` (the loader repeats numba's registration of its C
helpers, which the machine code calls on its error paths).

Format: the line ``DCS-NATIVE-IMAGE 1``, one line of JSON (the key and, per entry point, its
symbol, offset, size and SHA-256: a damaged image is not loaded), then the object files back to
back. Written to a temporary file and renamed (atomic; concurrent writers write the same bytes).
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

from .vendored import cache_file, write_atomic

__all__ = ["ENV", "MAGIC", "NUMBA_RELEASES", "image_path", "native_addresses", "provide",
           "read_image", "sources", "write_image"]

ENV = "DRILLCOSIM_NATIVE_IMAGE"
MAGIC = b"DCS-NATIVE-IMAGE 1\n"

_ENGINES: list[Any] = []  # the MCJIT engines of the loaded images, alive as long as the process
_LOADED: dict[Path, dict[str, int]] = {}  # image path -> addresses (one load per process)
_SYMBOLS_READY = False
_PROVIDED: dict[str, str] = {}  # module name -> where its entry points came from


#: The numba releases whose C-helper registration :func:`_prepare_symbols` repeats (checked
#: with 0.68; the same since before the project's minimum, 0.58). With another release the
#: compiled steps come from numba, as without images.
NUMBA_RELEASES = ((0, 58), (0, 68))


def enabled() -> bool:
    """Whether native images are used: ``$DRILLCOSIM_NATIVE_IMAGE`` is not ``0`` (default on)
    and numba's release is one of :data:`NUMBA_RELEASES`."""
    if os.environ.get(ENV, "1").strip() == "0":
        return False
    import numba

    try:
        release = tuple(int(x) for x in numba.__version__.split(".")[:2])
    except ValueError:
        return False
    return NUMBA_RELEASES[0] <= release <= NUMBA_RELEASES[1]


def target_key() -> dict[str, Any]:
    """What an image's machine code depends on besides the package's code: the versions of
    Python, numba and llvmlite, and numba's target description (triple, CPU name, features;
    numba's ``NUMBA_CPU_NAME`` / ``NUMBA_CPU_FEATURES`` override the host's as for numba)."""
    import llvmlite
    import llvmlite.binding as ll
    import numba
    from numba.core import codegen, config

    return {
        "python": list(sys.version_info[:2]) + [getattr(sys, "abiflags", "")],
        "numba": numba.__version__,
        "llvmlite": llvmlite.__version__,
        "target": [ll.get_process_triple(), config.CPU_NAME or ll.get_host_cpu_name(),
                   config.CPU_FEATURES or codegen.get_host_cpu_features()],
    }


def image_path(package: ModuleType, entries: Sequence[str]) -> Path:
    """The image file of the cfuncs ``entries`` of the imported vendored ``package``: in the
    folder that holds the package (its stable copy), named by :func:`target_key` and the
    entries."""
    key = json.dumps({"entries": list(entries), **target_key()}, sort_keys=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    return cache_file(package, f"native-{package.__name__}-{digest}.bin")


def _prepare_symbols() -> None:
    """Make numba's C helpers known to LLVM, as numba's own set-up does (``_load_global_helpers``
    and the runtime's ``initialize``): the images' machine code calls them by name."""
    global _SYMBOLS_READY
    if _SYMBOLS_READY:
        return
    import builtins

    import llvmlite.binding as ll
    from numba import _dynfunc, _helperlib
    from numba.core.runtime import _nrt_python

    ll.initialize_native_target()
    ll.initialize_native_asmprinter()
    ll.add_symbol("_Py_NoneStruct", id(None))
    for helpers in (_helperlib.c_helpers, _dynfunc.c_helpers):
        for name, address in helpers.items():
            ll.add_symbol("numba_" + name, address)
    for name, address in _nrt_python.c_helpers.items():
        ll.add_symbol(name if name.startswith("_") else "NRT_" + name, address)
    for obj in builtins.__dict__.values():
        if isinstance(obj, type) and issubclass(obj, BaseException):
            ll.add_symbol(f"PyExc_{obj.__name__}", id(obj))
    _SYMBOLS_READY = True


def read_image(path: Path, entries: Sequence[str]) -> dict[str, int] | None:
    """Load the image at ``path``; the addresses of ``entries``, or None if it is missing,
    unreadable, of another key, cut, damaged (an object's SHA-256 differs) or lacks an entry
    (the caller falls back to numba)."""
    path = Path(path)
    if path in _LOADED:
        return _LOADED[path]
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if not data.startswith(MAGIC):
        return None
    try:
        end = data.index(b"\n", len(MAGIC))
        header = json.loads(data[len(MAGIC):end])
    except ValueError:
        return None
    body = memoryview(data)[end + 1:]
    try:
        table = header["entries"]
        if header["key"] != target_key() or any(e not in table for e in entries):
            return None
        if any(v["offset"] + v["size"] > len(body) for v in table.values()):
            return None  # truncated
        objects = {name: bytes(body[table[name]["offset"]:
                                    table[name]["offset"] + table[name]["size"]])
                   for name in entries}
        if any(hashlib.sha256(obj).hexdigest() != table[name]["sha256"]
               for name, obj in objects.items()):
            return None  # damaged: machine code is loaded only as it was written
    except (KeyError, TypeError, AttributeError):  # a header not of this format
        return None
    import llvmlite.binding as ll

    _prepare_symbols()
    triple, cpu, features = header["key"]["target"]
    addresses = {}
    for name in entries:
        entry = table[name]
        # an engine takes its target machine over (llvmlite): one each
        machine = ll.Target.from_triple(triple).create_target_machine(cpu=cpu, features=features,
                                                                      jit=True)
        engine = ll.create_mcjit_compiler(ll.parse_assembly(""), machine)
        try:
            engine.add_object_file(ll.ObjectFileRef.from_data(objects[name]))
            engine.finalize_object()
        except RuntimeError:  # LLVM refused the object: numba's path instead
            return None
        address = engine.get_function_address(entry["symbol"])
        _ENGINES.append(engine)
        if not address:
            return None
        addresses[name] = address
    _LOADED[path] = addresses
    return addresses


def _object_code(cf: Any) -> bytes | None:
    """The object code numba cached for the cfunc ``cf`` (None: not cached, e.g. an unwritable
    cache folder)."""
    cache = cf._cache
    if getattr(cache, "_cache_file", None) is None:  # numba's NullCache: caching off
        return None
    codegen = cf._targetdescr.target_context.codegen()
    if codegen.magic_tuple() != tuple(target_key()["target"]):
        return None
    data = cache._cache_file.load(cache._index_key(cf._sig, codegen))
    if data is None:
        return None
    _name, kind, payload = data[0]  # CompileResult._reduce(): the library first
    return payload[0] if kind == "object" else None


def write_image(path: Path, cfuncs: Mapping[str, Any]) -> bool:
    """Write the image of the numba cfuncs ``cfuncs`` (entry point -> ``numba.cfunc``) to
    ``path``; whether it was written (not if numba cached no object code or the folder is not
    writable)."""
    table, blobs, offset = {}, [], 0
    for name, cf in cfuncs.items():
        try:
            obj = _object_code(cf)
        except (AttributeError, LookupError, OSError, ValueError, EOFError,
                pickle.UnpicklingError):  # numba's cache not as this code reads it: no image
            return False
        if obj is None:
            return False
        table[name] = {"symbol": cf.native_name, "offset": offset, "size": len(obj),
                       "sha256": hashlib.sha256(obj).hexdigest()}
        blobs.append(obj)
        offset += len(obj)
    header = json.dumps({"key": target_key(), "entries": table}, sort_keys=True).encode()
    return write_atomic(Path(path), MAGIC + header + b"\n" + b"".join(blobs))


def native_addresses(package: ModuleType, entries: Sequence[str],
                     cfuncs: Callable[[], Mapping[str, Any]]) -> tuple[dict[str, int], str]:
    """Addresses of the compiled entry points ``entries`` of the vendored ``package``.

    From its native image when there is a valid one; else from numba (``cfuncs()``: entry
    point -> ``numba.cfunc``, compiled or loaded from numba's cache), writing the image for the
    next process.

    Returns
    -------
    addresses : dict of str to int
        Entry point -> address of its C function.
    source : str
        ``"image"`` or ``"numba"``.
    """
    path = image_path(package, entries) if enabled() else None
    if path is not None:
        found = read_image(path, entries)
        if found is not None:
            return dict(found), "image"
    made = cfuncs()
    if path is not None:
        write_image(path, {e: made[e] for e in entries})
    return {e: made[e].address for e in entries}, "numba"


def provide(package: ModuleType, module: ModuleType) -> str:
    """Give the compiled entry points of ``module`` their addresses, once per process.

    ``module`` is a module of the vendored ``package`` with ``ENTRIES`` (names of its
    entry points), ``cfuncs()`` (them as numba cfuncs) and ``use_addresses(mapping)``
    (``plant.compiled_step``, ``controller.compiled``). Returns where the addresses came from:
    ``"image"`` or ``"numba"`` (:func:`native_addresses`).
    """
    if module.__name__ not in _PROVIDED:
        found, source = native_addresses(package, module.ENTRIES, module.cfuncs)
        module.use_addresses(found)
        _PROVIDED[module.__name__] = source
    return _PROVIDED[module.__name__]


def sources() -> dict[str, str]:
    """Module -> where its compiled entry points came from in this process (``"image"`` or
    ``"numba"``), for the modules given addresses by :func:`provide`."""
    return dict(_PROVIDED)
