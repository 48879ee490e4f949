"""Atomic files: a file appears under its name complete, or not at all.

:class:`AtomicFile` writes to a temporary file in the target's folder (so the final rename
stays on one file system) and, on :meth:`~AtomicFile.commit`, flushes it to disk, gives it the
permissions an ordinary ``open`` would have (``0o666`` minus the umask; ``mkstemp`` creates
``0o600``), renames it onto the target with ``os.replace`` and syncs the folder. Until then an
earlier file under the target name is untouched, and readers see the old or the new file,
never a part. :meth:`~AtomicFile.discard` (or an exception inside a ``with`` block) deletes the
temporary file and leaves the target alone. :func:`atomic_write` does the whole thing for data
already in memory.

Every file the master, the scenario and the study layers publish goes through here (results,
summaries, plots, sweep tables, SSP archives).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import IO, Any

__all__ = ["AtomicFile", "atomic_write"]


def _default_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory file descriptors
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


class AtomicFile:
    """A file written under a temporary name and moved onto ``path`` when committed.

    Parameters
    ----------
    path : str or Path
        The target.
    mode : {"w", "wb"}
        Text or binary.
    **open_kwargs
        Passed to ``os.fdopen`` (e.g. ``newline=""``, ``encoding``).

    Raises
    ------
    OSError
        If the temporary file cannot be created (the message names the target and its
        folder); nothing is written then.

    Examples
    --------
    >>> with AtomicFile("out.json") as fh:    # doctest: +SKIP
    ...     fh.write("{}")
    """

    def __init__(self, path: str | os.PathLike, mode: str = "w", **open_kwargs: Any):
        if mode not in ("w", "wb"):
            raise ValueError(f"mode: 'w' or 'wb', got {mode!r}")
        self.path = Path(path)
        folder = self.path.parent
        try:
            fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{self.path.name}.", suffix=".part")
        except OSError as exc:
            raise OSError(exc.errno, f"cannot write '{self.path}': folder '{folder}' is not "
                          f"writable ({exc.strerror})") from exc
        self.tmp_path = Path(tmp)
        try:
            self.file: IO[Any] = os.fdopen(fd, mode, **open_kwargs)
        except BaseException:
            os.close(fd)
            self.tmp_path.unlink(missing_ok=True)
            raise
        self.done = False

    def commit(self) -> Path:
        """Flush, sync and close the file, then rename it onto the target (once).

        Raises
        ------
        OSError
            If the last write or the sync fails; the temporary file is deleted and the target
            left as it was.
        """
        if self.done:
            return self.path
        try:
            self.file.flush()
            os.fsync(self.file.fileno())
            self.file.close()
            os.chmod(self.tmp_path, _default_mode())
            os.replace(self.tmp_path, self.path)
        except BaseException:
            self.discard()
            raise
        self.done = True
        _fsync_dir(self.path.parent)
        return self.path

    def discard(self) -> None:
        """Close and delete the temporary file; the target is not touched (idempotent)."""
        if self.done:
            return
        self.done = True
        try:
            self.file.close()
        except OSError:
            pass  # unflushed data of a file that is deleted anyway
        self.tmp_path.unlink(missing_ok=True)

    def __enter__(self) -> IO[Any]:
        return self.file

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


def atomic_write(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` (text as UTF-8, or bytes) to ``path`` atomically; returns the path."""
    with AtomicFile(path, "wb") as fh:
        fh.write(data.encode("utf-8") if isinstance(data, str) else data)
    return Path(path)
