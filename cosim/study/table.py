"""The sweep's results table: one CSV appended row by row, and a Parquet copy.

``results.csv`` is the record: a header line written atomically when the table
is created, then one line per finished point, each appended with a single
``write`` followed by ``flush`` + ``fsync``. A kill can at worst leave a partial
last line; :meth:`ResultTable.load` drops it (and any line with the wrong number
of fields) and rewrites the file atomically without it, so the table is never
corrupt and a resumed sweep simply re-runs that point.

Columns that need the open-loop reference of the same scene/engine/step/stop
time are derived (:func:`fill_benefit`, applied when a row is appended if the
reference is known, and again on reading): ``benefit_<span> = 1 - rms_<span> /
rms_<span>(open loop)`` (1 = all deflection removed, 0 = none, < 0 = worse),
``growth_excess`` and the final ``stable``. ``results.parquet`` holds all rows
with them filled in, rewritten atomically (temporary file + ``os.replace``)
after every row.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["COLUMNS", "ResultTable"]

#: Column order of the table (units: gain N/strain, times s, deflections m, force N, power W,
#: growth_rate 1/s).
COLUMNS: tuple[str, ...] = (
    "key", "scene", "engine", "kind", "gain", "delay", "step", "stop_time", "status",
    "stable", "growth_rate", "divergence_time", "end_time", "rms_long", "rms_short",
    "benefit_long", "benefit_short", "growth_excess", "peak_deflection_long", "peak_deflection_short",
    "peak_force", "peak_power", "wall_time", "reason",
)
_TEXT = {"key", "scene", "engine", "kind", "status", "reason"}
SPANS = ("long", "short")
#: A completed closed-loop run is unstable when its strain-envelope growth rate exceeds the
#: open-loop run's (same scene/engine/step/stop time) by more than this [1/s].
GROWTH_MARGIN = 0.5


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same folder + ``os.replace``."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def _format(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def _parse(col: str, text: str) -> Any:
    if col in _TEXT:
        return text
    if text == "":
        return math.nan
    return float(text)


def _line(row: Mapping[str, Any]) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([_format(row.get(c)) for c in COLUMNS])
    return buf.getvalue()


def fill_benefit(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Derived columns from the matching open-loop row (same scene/engine/step/stop).

    ``benefit_<span> = 1 - rms / rms_open``; ``growth_excess = growth_rate -
    growth_rate_open`` [1/s]; a completed closed-loop run with ``growth_excess >
    GROWTH_MARGIN`` gets ``stable = 0`` and a reason.
    """
    ref: dict[tuple, dict[str, Any]] = {}
    for r in rows:
        if r.get("kind") == "open_loop" and r.get("status") == "ok":
            ref[(r["scene"], r["engine"], r["step"], r["stop_time"])] = r
    for r in rows:
        o = ref.get((r.get("scene"), r.get("engine"), r.get("step"), r.get("stop_time")))
        for s in SPANS:
            b = math.nan
            if r.get("kind") == "closed_loop" and o is not None:
                rc, ro = r.get(f"rms_{s}", math.nan), o.get(f"rms_{s}", math.nan)
                if isinstance(rc, float) and isinstance(ro, float) and ro > 0:
                    b = 1.0 - rc / ro
            if r.get("kind") == "open_loop":
                b = 0.0 if r.get("status") == "ok" else math.nan
            r[f"benefit_{s}"] = b
        if r.get("kind") == "closed_loop" and r.get("status") == "ok":
            g0 = o.get("growth_rate", math.nan) if o is not None else math.nan
            ex = r.get("growth_rate", math.nan) - g0
            r["growth_excess"] = ex
            if math.isfinite(ex) and ex > GROWTH_MARGIN:
                r["stable"] = 0.0
                r["reason"] = (f"strain envelope grows {ex:.3g} 1/s faster than open loop "
                               f"(> {GROWTH_MARGIN:g} 1/s)")
            elif math.isfinite(ex):
                r["stable"] = 1.0
                r["reason"] = ""
    return rows


class ResultTable:
    """Append-only results table of a sweep folder.

    Parameters
    ----------
    folder : path-like
        Created if missing; holds ``results.csv`` and ``results.parquet``.
    """

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.csv_path = self.folder / "results.csv"
        self.parquet_path = self.folder / "results.parquet"
        self.rows: list[dict[str, Any]] = self.load()

    # -- reading -------------------------------------------------------------------
    def load(self) -> list[dict[str, Any]]:
        """Read the CSV (creating it if missing); drop and repair a partial last line.

        Returns
        -------
        list of dict
            One dict per complete row, numbers as float (NaN for empty cells).
        """
        header = _line(dict(zip(COLUMNS, COLUMNS)))
        if not self.csv_path.exists():
            atomic_write_bytes(self.csv_path, header.encode())
            return []
        raw = self.csv_path.read_bytes()
        text = raw.decode("utf-8", errors="replace")
        good_end = text.rfind("\n") + 1
        lines = text[:good_end].splitlines(keepends=True)
        rows: list[dict[str, Any]] = []
        kept = [header]
        bad = good_end != len(text)
        if not lines or lines[0] != header:
            raise ValueError(f"{self.csv_path}: not a sweep table (header differs); "
                             "use another --out folder")
        for line in lines[1:]:
            try:
                fields = next(csv.reader([line]))
            except (csv.Error, StopIteration):
                bad = True
                continue
            if len(fields) != len(COLUMNS):
                bad = True
                continue
            try:
                rows.append({c: _parse(c, v) for c, v in zip(COLUMNS, fields)})
            except ValueError:
                bad = True
                continue
            if any(r["key"] == rows[-1]["key"] for r in rows[:-1]):
                rows = [r for r in rows[:-1] if r["key"] != rows[-1]["key"]] + rows[-1:]
                bad = True      # a duplicate key: keep the newest row
            kept.append(line)
        if bad:
            kept = [header] + [_line(r) for r in rows]
            atomic_write_bytes(self.csv_path, "".join(kept).encode())
        return rows

    def lock(self):
        """Exclusive lock of the folder for one writing sweep (``OSError`` if taken).

        Returns the open lock file; closing it releases the lock.
        """
        import fcntl

        fh = open(self.folder / ".sweep.lock", "w")
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            raise OSError(f"{self.folder}: another sweep is writing to this folder") from None
        return fh

    def keys(self, include_errors: bool = True) -> set[str]:
        """Keys of the finished points (optionally without the ``error`` rows)."""
        return {r["key"] for r in self.rows if include_errors or r["status"] != "error"}

    # -- writing -------------------------------------------------------------------
    def append(self, row: Mapping[str, Any]) -> dict[str, Any]:
        """Append one finished point (fsync'ed) and refresh the Parquet copy.

        A row whose key is already present replaces it (a retried error).
        """
        full = {c: row.get(c, "" if c in _TEXT else math.nan) for c in COLUMNS}
        known = [r for r in self.rows if r["key"] == full["key"]]
        if known:
            self.rows = [r for r in self.rows if r["key"] != full["key"]]
            self.rows.append(full)
            fill_benefit(self.rows)
            self._rewrite_csv()
        else:
            self.rows.append(full)
            fill_benefit(self.rows)
            with open(self.csv_path, "a", encoding="utf-8") as fh:
                fh.write(_line(full))
                fh.flush()
                os.fsync(fh.fileno())
        self.write_parquet()
        return full

    def _rewrite_csv(self) -> None:
        text = _line(dict(zip(COLUMNS, COLUMNS))) + "".join(_line(r) for r in self.rows)
        atomic_write_bytes(self.csv_path, text.encode())

    def write_parquet(self) -> Path:
        """Write all rows (benefit filled) to ``results.parquet`` atomically."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        rows = fill_benefit([dict(r) for r in self.rows])
        cols = {c: pa.array([r[c] for r in rows], type=pa.string() if c in _TEXT
                            else pa.float64()) for c in COLUMNS}
        buf = pa.BufferOutputStream()
        pq.write_table(pa.table(cols), buf)
        atomic_write_bytes(self.parquet_path, buf.getvalue().to_pybytes())
        return self.parquet_path


def read_table(folder_or_file: str | os.PathLike) -> list[dict[str, Any]]:
    """Rows of a sweep (folder, ``results.csv`` or ``results.parquet``), benefit filled."""
    p = Path(folder_or_file)
    if p.suffix == ".parquet":
        import pyarrow.parquet as pq

        return pq.read_table(p).to_pylist()
    folder = p.parent if p.suffix == ".csv" else p
    return fill_benefit(ResultTable(folder).rows)
