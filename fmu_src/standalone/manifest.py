"""The MANIFEST of a self-contained FMU's runtime: what the C wrapper checks before loading it.

The format is the one ``fmu_src/wrapper/dcs_runtime.c`` reads (its top comment): ``key value``
lines (``dcs-runtime 1`` first), one ``file <sha256> <size> <path>`` line per file of the
runtime (paths relative to the runtime folder, ``/``-separated, sorted), and a last line
``end <sha256 of every byte before it>`` that makes a damaged MANIFEST itself detectable.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

__all__ = ["MANIFEST", "file_sha256", "read_manifest", "write_manifest"]

MANIFEST = "MANIFEST"  #: the MANIFEST's file name in the runtime folder
_CHUNK = 1 << 20


def file_sha256(path: Path) -> str:
    """SHA-256 of a file (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(_CHUNK), b""):
            digest.update(block)
    return digest.hexdigest()


def write_manifest(root: Path, items: Sequence[tuple[str, str]],
                   exclude: Iterable[str] = ()) -> Path:
    """Write ``root/MANIFEST`` listing every file under ``root``.

    Parameters
    ----------
    root : Path
        The runtime folder.
    items : sequence of (str, str)
        The ``key value`` lines before the file lines, in order (``platform``, ``python``,
        ``library``, ...); ``dcs-runtime 1`` is written first by this function.
    exclude : iterable of str
        Relative paths not listed (none by default; the MANIFEST itself never is).

    Returns
    -------
    Path
        The MANIFEST.
    """
    skip = {MANIFEST, *exclude}
    lines = ["dcs-runtime 1"] + [f"{key} {value}" for key, value in items]
    for path in sorted(p for p in root.rglob("*") if p.is_file() or p.is_symlink()):
        rel = path.relative_to(root).as_posix()
        if rel in skip:
            continue
        if path.is_symlink() or not path.is_file():
            raise ValueError(f"{path}: the runtime may hold regular files only")
        lines.append(f"file {file_sha256(path)} {path.stat().st_size} {rel}")
    body = ("\n".join(lines) + "\n").encode()
    text = body + f"end {hashlib.sha256(body).hexdigest()}\n".encode()
    out = root / MANIFEST
    tmp = out.with_suffix(".tmp")
    tmp.write_bytes(text)
    os.replace(tmp, out)
    return out


def read_manifest(path: Path) -> tuple[list[tuple[str, str]], dict[str, tuple[str, int]]]:
    """``(items, files)`` of a MANIFEST: the ``key value`` lines and ``{path: (sha256,
    size)}``.

    Raises
    ------
    ValueError
        Not a MANIFEST, or one whose end line does not match its content.
    """
    data = Path(path).read_bytes()
    head, sep, end = data.rpartition(b"end ")
    if not data.startswith(b"dcs-runtime 1\n") or not sep or \
            end.strip().decode() != hashlib.sha256(head).hexdigest():
        raise ValueError(f"{path}: not a runtime MANIFEST, or a damaged one")
    items: list[tuple[str, str]] = []
    files: dict[str, tuple[str, int]] = {}
    for line in head.decode().splitlines()[1:]:
        key, _, value = line.partition(" ")
        if key == "file":
            digest, size, rel = value.split(" ", 2)
            files[rel] = (digest, int(size))
        else:
            items.append((key, value))
    return items, files
