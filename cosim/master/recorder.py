"""Recording observer: requested variables at a fixed output interval.

Rows are kept as a structured numpy array with ``'time'`` first (so
``fmpy.util.plot_result`` accepts it) and can be streamed to a CSV file.

The CSV is written atomically (:class:`cosim.master.files.AtomicFile`): rows go to a
temporary file in the target's directory, flushed every ``flush_every`` rows (memory
stays flat when ``keep_in_memory=False``), and :meth:`Recorder.close` renames it onto
the target. An earlier file under the target name is thus
never truncated before the new one is complete; if the run fails, closing
(which the facade does in a ``finally``) still finalises the partial,
readable file under the target name.

The text of a block of rows is made by :class:`CsvWriter` in a thread, in C without the GIL
(:mod:`cosim.master.native`, ``rows.c``: the text of ``numpy.savetxt(fmt="%.17g")``), while
the run steps on; blocks are written in order, and each flush first waits for the block before
it, so a failed write is raised at the next flush (or at :meth:`Recorder.close`), always the
same one. Without the native library the rows are written at once in Python.

If writing the CSV fails (disk full, quota, I/O error), the recorder raises
:class:`ResultWriteError` (a :class:`~cosim.master.errors.CosimError`: when it happens
while stepping, the facade attaches the rows recorded in memory as
``error.result``; when the final write in :meth:`Recorder.close` fails, the
rows stay in :attr:`Recorder.data`), deletes
its temporary file (freeing the space; it may end in a cut row) and never
replaces the target: an earlier file under the target name stays unchanged.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .errors import CosimError
from .files import AtomicFile
from .system import split_variable


class ResultWriteError(CosimError):
    """Writing the result CSV failed (e.g. ``ENOSPC``); the run stopped.

    Attributes
    ----------
    path : Path
        The target CSV (left unchanged: an earlier file under that name survives).
    os_errno : int or None
        ``errno`` of the underlying ``OSError``.
    """

    def __init__(self, path: str | Path, time: float, reason: str,
                 os_errno: int | None = None):
        super().__init__("", "write results", time, reason)
        self.path = Path(path)
        self.os_errno = os_errno
        self.args = (f"cannot write results to '{self.path}' (last row at t = {time:.9g} s): "
                     f"{reason}",)

    def __reduce__(self):
        return (type(self), (self.path, self.time, self.message, self.os_errno))


class CsvWriter:
    """Appends row blocks to an open text file in a thread, in order (see the module docstring).

    Parameters
    ----------
    file : text file
        Open for writing; only this writer writes to it until :meth:`close`.
    format_rows : ctypes function
        ``dcs_format_rows`` of the native library.
    """

    #: bytes that hold one value and its separator (``rows.c``)
    VALUE_BYTES = 25

    def __init__(self, file, format_rows):
        self.file = file
        self.format_rows = format_rows
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="csv-writer")
        self._pending: Future | None = None

    def _write(self, rows: np.ndarray) -> None:
        n, ncols = rows.shape
        cap = n * (ncols * self.VALUE_BYTES + 1)
        buf = ctypes.create_string_buffer(cap)
        length = self.format_rows(rows.ctypes.data, n, ncols, buf, cap)   # GIL released
        if length < 0:
            raise RuntimeError("internal: dcs_format_rows ran out of room")
        self.file.write(buf.raw[:length].decode("ascii"))
        self.file.flush()

    def submit(self, rows: np.ndarray) -> None:
        """Wait for the block before (raising its ``OSError``), then start writing ``rows``
        (shape (n, ncols), float64)."""
        self.wait()
        self._pending = self._pool.submit(self._write, np.ascontiguousarray(rows, np.float64))

    def wait(self) -> None:
        """Wait for the block being written; raise its ``OSError``."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending.result()

    def close(self) -> None:
        """Stop the thread (after the block being written; its error is not raised)."""
        try:
            self.wait()
        except Exception:  # noqa: BLE001 - closing after a failure: nothing more to report
            pass
        self._pool.shutdown()


class Recorder:
    """Observer recording variables every ``interval_ticks`` base steps.

    Parameters
    ----------
    variables : sequence of str
        ``'fmu.var'`` Real variables to record.
    interval_ticks : int
        Output interval in base steps (>= 1).
    csv_path : str or Path, optional
        Stream rows to this CSV file (comma separated, header line, values
        with 17 significant digits).
    flush_every : int
        Rows buffered before they are written to the CSV.
    keep_in_memory : bool
        Keep all rows for :attr:`data`; if False only the CSV holds them.

    Raises
    ------
    OSError
        If the CSV's directory is not writable (raised here, before any
        simulation), with the path in the message.
    """

    def __init__(self, variables: Sequence[str], interval_ticks: int = 1,
                 csv_path: str | Path | None = None, flush_every: int = 1000,
                 keep_in_memory: bool = True):
        if isinstance(interval_ticks, bool) or not isinstance(interval_ticks, int) \
                or interval_ticks < 1:
            raise ValueError(f"interval_ticks: integer >= 1, got {interval_ticks!r}")
        if flush_every < 1:
            raise ValueError(f"flush_every: integer >= 1, got {flush_every!r}")
        self.variables = list(variables)
        for v in self.variables:
            split_variable(v, "Recorder.variables")
        self.names = ["time", *self.variables]
        self.dtype = np.dtype([(n, np.float64) for n in self.names])
        self.interval_ticks = interval_ticks
        self.flush_every = flush_every
        self.keep_in_memory = keep_in_memory
        self._rows: list[tuple[float, ...]] = []     # rows not yet flushed (newest)
        self._blocks: list[np.ndarray] = []           # row blocks not yet flushed (older)
        self._n_blocked = 0                           # rows in _blocks
        self._chunks: list[np.ndarray] = []           # flushed rows kept in memory
        self.n_rows = 0
        self.csv_path = Path(csv_path) if csv_path is not None else None
        self._csv: AtomicFile | None = None
        self._writer: CsvWriter | None = None
        self._last_time = float("nan")
        self.write_error: ResultWriteError | None = None
        self.closed = False
        if self.csv_path is not None:
            self._open_csv()

    def _open_csv(self) -> None:
        target = self.csv_path
        try:
            self._csv = AtomicFile(target, "w", newline="")
        except OSError as exc:
            directory = target.parent if str(target.parent) else Path(".")
            raise OSError(exc.errno, f"cannot write results to '{target}': directory "
                          f"'{directory}' is not writable ({exc.strerror})") from exc
        self._csv.file.write(",".join(self.names) + "\n")
        from .native import library

        lib = library()
        if lib is not None:
            self._writer = CsvWriter(self._csv.file, lib.dcs_format_rows)

    # -- observer hooks --------------------------------------------------------
    def on_start(self, execution) -> None:
        """Resolve variables to fast indices; record the initial row."""
        index = getattr(execution.algorithm, "y_index", {})
        self._y = execution.algorithm.y
        self._fast = [index.get(v, -1) for v in self.variables]
        self._slow = {i: v for i, v in enumerate(self.variables) if self._fast[i] < 0}
        if execution.tick % self.interval_ticks == 0:
            self.on_step(execution)

    def on_step(self, execution) -> None:
        """Record a row when the tick is a multiple of the interval."""
        if execution.tick % self.interval_ticks:
            return
        y = self._y
        self._last_time = execution.time
        if self._slow:
            row = [execution.time]
            for i, j in enumerate(self._fast):
                row.append(y[j] if j >= 0 else execution.get_real(self._slow[i]))
            self._rows.append(tuple(row))
        else:
            self._rows.append((execution.time, *[y[j] for j in self._fast]))
        self.n_rows += 1
        if len(self._rows) >= self.flush_every:
            self.flush()

    def exchanged_columns(self, y_index) -> list[int] | None:
        """Indices in the exchange buffer of the recorded variables (``y_index``: the
        algorithm's name -> index), or None if one is not exchanged (read by name)."""
        columns = [y_index.get(v, -1) for v in self.variables]
        return None if min(columns, default=0) < 0 else columns

    def add_rows(self, block: np.ndarray) -> None:
        """Record rows made elsewhere (the native loop): shape (n, 1 + len(variables)),
        float64, time first; the same as :meth:`on_step` recording them one by one."""
        if not len(block):
            return
        if self._rows:
            self._blocks.append(np.array(self._rows, dtype=self.dtype))
            self._n_blocked += len(self._rows)
            self._rows = []
        rows = np.ascontiguousarray(block, dtype=np.float64).view(self.dtype).reshape(-1)
        self._blocks.append(rows)
        self._n_blocked += len(rows)
        self.n_rows += len(rows)
        self._last_time = float(rows["time"][-1])
        if self._n_blocked >= self.flush_every:
            self.flush()

    def on_stop(self, execution) -> None:
        """Flush buffered rows (the file is finalised by :meth:`close`)."""
        self.flush()

    # -- storage -----------------------------------------------------------------
    def _pending(self) -> list[np.ndarray]:
        """The rows not flushed yet, oldest first."""
        parts = list(self._blocks)
        if self._rows:
            parts.append(np.array(self._rows, dtype=self.dtype))
        return parts

    def flush(self) -> None:
        """Move buffered rows to the in-memory array and/or the CSV file."""
        parts = self._pending()
        if not parts:
            return
        chunk = parts[0] if len(parts) == 1 else np.concatenate(parts)
        self._rows, self._blocks, self._n_blocked = [], [], 0
        if self.keep_in_memory:
            self._chunks.append(chunk)
        if self._csv is not None:
            flat = chunk.view(np.float64).reshape(len(chunk), len(self.names))
            try:
                if self._writer is not None:
                    self._writer.submit(flat)
                else:
                    np.savetxt(self._csv.file, flat, delimiter=",", fmt="%.17g")
                    self._csv.file.flush()
            except OSError as exc:
                self._write_failed(exc)

    def _stop_writer(self) -> None:
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.close()

    def _write_failed(self, exc: OSError) -> None:
        """Drop the temporary file (never the target) and raise :class:`ResultWriteError`."""
        self._stop_writer()
        csv, self._csv = self._csv, None
        csv.discard()
        kept = "kept in memory" if self.keep_in_memory else "lost (keep_in_memory=False)"
        reason = (f"{exc.strerror or exc} (errno {exc.errno}); {self.n_rows} rows recorded "
                  f"({kept}); the target file was not replaced")
        self.write_error = ResultWriteError(self.csv_path, self._last_time, reason, exc.errno)
        raise self.write_error from exc

    @property
    def data(self) -> np.ndarray:
        """Recorded rows, shape (n_rows,), structured dtype ``time`` first [s]."""
        parts = self._chunks + self._pending()
        if not parts:
            return np.zeros(0, dtype=self.dtype)
        return np.concatenate(parts)

    def rows_since(self, start: int) -> np.ndarray:
        """The rows recorded from row ``start`` on (a copy; all of them: :attr:`data`)."""
        parts, first = [], 0
        for part in self._chunks + self._pending():
            if first + len(part) > start:
                parts.append(part[max(start - first, 0):])
            first += len(part)
        return np.concatenate(parts) if parts else np.zeros(0, dtype=self.dtype)

    def abort(self) -> None:
        """Drop the temporary CSV without touching the target (nothing was run)."""
        if self.closed:
            return
        self.closed = True
        self._stop_writer()
        if self._csv is not None:
            self._csv.discard()
            self._csv = None

    def close(self) -> None:
        """Flush and atomically move the CSV onto its target name (idempotent).

        Raises
        ------
        ResultWriteError
            If the last rows cannot be written; the target is not replaced.
        """
        if self.closed:
            return
        self.closed = True
        self.flush()
        if self._writer is not None:
            try:
                self._writer.wait()
            except OSError as exc:
                self._write_failed(exc)
            self._stop_writer()
        if self._csv is not None:
            try:
                self._csv.commit()
            except OSError as exc:
                self._write_failed(exc)
            self._csv = None
