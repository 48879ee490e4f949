"""The sweep's results table: ``results.csv``, and ``results.parquet`` with the same rows.

Each row is one finished point. Its *measured* columns come from the point measurement
(:func:`cosim.study.point.measure_point`); its *derived* columns (``verdict``, ``stable``,
``growth_excess``, ``benefit_<span>`` and, for completed runs, ``reason``) are a function
of that row and the open-loop reference row of the same scene, engine, step, stop time and
overrides (:func:`derive`), never of the order the points finished in. Whenever a row is
added, every row's derived columns are computed again: if only the new row has derived
values, its line is appended to the CSV (one ``write``, ``flush`` + ``fsync``); if an older
row's changed (its reference arrived), the CSV is rewritten atomically
(:func:`cosim.master.files.atomic_write`). The Parquet copy is rewritten atomically from the
same rows after every change, so both files hold the same table.

A kill can at worst leave a partial last CSV line, or a Parquet copy one row behind:
reading the table (:class:`ResultTable`, :func:`read_table`) drops the partial line, keeps the
newest of duplicate keys and recomputes the derived columns; a writing sweep (holding the
folder's lock, :meth:`ResultTable.load` with ``repair=True``) also rewrites whichever file
differs from the result. A resumed sweep thus re-runs that point and re-judges the rows it
depends on; a reader never writes (it may run while a sweep appends).

``benefit_<span> = 1 - rms_<span> / rms_<span>(open loop)`` (1 = all deflection removed,
0 = none, < 0 = worse); ``growth_excess = growth_rate - growth_rate(open loop)`` [1/s];
``verdict`` and ``stable`` (1 stable, 0 unstable, NaN otherwise), ``agrees_with_prediction`` (1, 0,
NaN: not compared) with its ``prediction_note``, and ``benefit_note`` (why a benefit cannot be
judged, "" if it can): :mod:`cosim.study.verdict`. Measured besides the metrics
(:func:`cosim.study.point.measure_point`): ``predicted_growth_rate`` [1/s], ``contact_time`` [s],
``rms_rise_<span>`` [1], and the point's ``wall_time`` split into ``startup_time`` (configuration,
build, FMU instantiation and initialization) and ``stepping_time`` [s], plus ``worker_startup``
[s] (the worker process's start, imports included, before its first point; NaN for the others)
and ``branch_time`` [s] (the point continued from a shared prefix's checkpoint at that time,
:mod:`cosim.study.branch`; NaN: run from the start).
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Collection, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from drillcosim.cosim.master.files import atomic_write

from .verdict import VERDICTS, benefit_note, compare_with_prediction, judge

__all__ = ["COLUMNS", "DERIVED", "ResultTable", "derive", "notes", "read_table", "rows_csv",
           "verdict_counts"]

#: Column order of the table (units: gain that of the sweep's gain key (N/strain for the strain
#: gain), times s, deflections m, force N, power W, growth rates 1/s, stick-slip measures 1;
#: ``varied``: the point's values of the sweep's other axes, JSON by key path).
COLUMNS: tuple[str, ...] = (
    "key", "scene", "engine", "kind", "gain", "delay", "step", "stop_time", "varied", "status",
    "verdict", "stable", "growth_rate", "growth_noise", "growth_excess",
    "predicted_growth_rate", "agrees_with_prediction", "prediction_note", "divergence_time",
    "end_time", "min_stop_time", "contact_time", "rms_long", "rms_short", "benefit_long",
    "benefit_short", "rms_rise_long", "rms_rise_short", "benefit_note",
    "peak_deflection_long", "peak_deflection_short", "peak_force", "peak_power",
    "stick_slip_severity", "stick_fraction", "wall_time", "startup_time", "stepping_time",
    "worker_startup", "branch_time", "reason",
)
#: Columns computed from the rows by :func:`derive` (``reason`` too, for completed runs;
#: ``prediction_note`` where the point has a prediction).
DERIVED: tuple[str, ...] = ("verdict", "stable", "growth_excess", "agrees_with_prediction",
                            "benefit_long", "benefit_short", "benefit_note")
_TEXT = {"key", "scene", "engine", "kind", "varied", "status", "verdict", "prediction_note",
         "benefit_note", "reason"}
SPANS = ("long", "short")
_STABLE = {"stable": 1.0, "unstable": 0.0}


def _format(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def _parse(col: str, text: str, text_columns: Collection[str] = _TEXT) -> Any:
    if col in text_columns:
        return text
    if text == "":
        return math.nan
    return float(text)


def _line(row: Mapping[str, Any], columns: Sequence[str] = COLUMNS) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([_format(row.get(c)) for c in columns])
    return buf.getvalue()


def _csv_text(rows: Iterable[Mapping[str, Any]], columns: Sequence[str] = COLUMNS) -> str:
    return _line(dict(zip(columns, columns)), columns) + "".join(_line(r, columns) for r in rows)


def full_row(row: Mapping[str, Any], columns: Sequence[str] = COLUMNS,
             text_columns: Collection[str] = _TEXT) -> dict[str, Any]:
    """``row`` with every column of ``columns`` (missing numbers NaN, missing text '')."""
    return {c: row.get(c, "" if c in text_columns else math.nan) for c in columns}


def reference_key(key: str) -> str:
    """Key of the open-loop reference of a point's key (:func:`cosim.study.grid.point_key`)."""
    scene, engine, _kind, _gain, _delay, rest = key.split("|", 5)
    return "|".join((scene, engine, "open_loop", "0", "0", rest))


def derive(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Rows with their derived columns computed from the measured ones (new dicts, same order).

    The result depends on the set of rows only: every row is judged against the open-loop row
    whose key is :func:`reference_key` of its own (:func:`cosim.study.verdict.judge`).
    """
    by_key = {r["key"]: r for r in rows}
    out = []
    for r in rows:
        d = full_row(r)
        ref = by_key.get(reference_key(d["key"])) if d["kind"] == "closed_loop" else None
        verdict, reason, excess = judge(d, ref)
        d["verdict"], d["stable"] = verdict, _STABLE.get(verdict, math.nan)
        if verdict == "reference":
            d["stable"] = 1.0
        if d["status"] == "ok":
            d["reason"] = reason
        d["growth_excess"] = excess
        d["agrees_with_prediction"] = math.nan
        d["benefit_note"] = ""
        if d["kind"] == "closed_loop":
            d["agrees_with_prediction"], d["prediction_note"] = compare_with_prediction(
                d, verdict, excess)
        ok_ref = ref is not None and ref.get("status") == "ok"
        judged = []
        for s in SPANS:
            b = math.nan
            if d["kind"] == "open_loop":
                b = 0.0 if d["status"] == "ok" else math.nan
            elif ok_ref:
                rc, ro = d[f"rms_{s}"], ref.get(f"rms_{s}", math.nan)
                if isinstance(rc, float) and isinstance(ro, float) and ro > 0:
                    b = 1.0 - rc / ro
                    judged.append(s)
            d[f"benefit_{s}"] = b
        d["benefit_note"] = benefit_note(ref, judged) if judged else ""
        out.append(d)
    return out


def notes(rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """One line each: the closed-loop points whose verdict differs from the linear prediction
    (counted by reason), and those whose benefit cannot be judged (the first reason)."""
    closed = [r for r in rows if r["kind"] == "closed_loop"]
    out = []
    differ: dict[str, int] = {}
    for r in closed:
        if r["agrees_with_prediction"] == 0.0:
            why = str(r["prediction_note"]).split(":", 1)[0]
            differ[why] = differ.get(why, 0) + 1
    if differ:
        out.append(f"{sum(differ.values())} of {len(closed)} points differ from the linear "
                   f"prediction ({', '.join(f'{n} {w}' for w, n in differ.items())}; "
                   "prediction_note in the table)")
    unjudged = [r for r in closed if r["benefit_note"]]
    if unjudged:
        out.append(f"benefit not judged at {len(unjudged)} of {len(closed)} points: "
                   f"{unjudged[0]['benefit_note']}")
    return out


def verdict_counts(rows: Iterable[Mapping[str, Any]]) -> dict[str, int]:
    """Number of rows per verdict (every value of :data:`cosim.study.verdict.VERDICTS`)."""
    counts = dict.fromkeys(VERDICTS, 0)
    for r in rows:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    return counts


def _same(a: Mapping[str, Any], b: Mapping[str, Any], columns: Sequence[str] = COLUMNS) -> bool:
    """Equal rows (NaN equal to NaN)."""
    for c in columns:
        x, y = a.get(c), b.get(c)
        if x != y and not (isinstance(x, float) and isinstance(y, float)
                           and math.isnan(x) and math.isnan(y)):
            return False
    return True


class ResultTable:
    """The results table of a sweep folder.

    The table's schema is three class attributes, so another study keeps its own columns
    with the same files, lock, repair and order-independent derivation (a subclass sets
    ``columns``, ``text_columns`` and ``derive``; a row's identity is its ``key`` column).

    Parameters
    ----------
    folder : path-like
        Created if missing; holds ``results.csv`` and ``results.parquet``.

    Attributes
    ----------
    rows : list of dict
        Every row, derived columns filled, in the order the points finished.
    columns : tuple of str
        Column order (class attribute; default :data:`COLUMNS`), ``key`` among them.
    text_columns : frozenset of str
        Columns stored as text; the others are floats (NaN when empty).
    """

    columns: tuple[str, ...] = COLUMNS
    text_columns: frozenset[str] = frozenset(_TEXT)

    @staticmethod
    def derive(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
        """The rows with their derived columns (a function of the set of rows: :func:`derive`)."""
        return derive(rows)

    def _full(self, row: Mapping[str, Any]) -> dict[str, Any]:
        return full_row(row, self.columns, self.text_columns)

    def _text(self, rows: Iterable[Mapping[str, Any]]) -> str:
        return _csv_text(rows, self.columns)

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.csv_path = self.folder / "results.csv"
        self.parquet_path = self.folder / "results.parquet"
        self.rows: list[dict[str, Any]] = self.load()

    # -- reading -------------------------------------------------------------------
    def load(self, repair: bool = False) -> list[dict[str, Any]]:
        """Read the CSV: complete rows, newest of a repeated key, derived columns recomputed.

        Parameters
        ----------
        repair : bool
            Also bring the files up to date (for the sweep holding the folder's lock): create
            the CSV if missing; rewrite it, and the Parquet copy, atomically where they differ
            from the rows read (a partial last line, stale derived columns, a lagging copy).

        Returns
        -------
        list of dict
            One dict per complete row, numbers as float (NaN for empty cells).
        """
        if not self.csv_path.exists():
            if repair:
                atomic_write(self.csv_path, self._text([]))
            return []
        text = self.csv_path.read_bytes().decode("utf-8", errors="replace")
        lines = text[: text.rfind("\n") + 1].splitlines(keepends=True)
        if not lines or lines[0] != self._text([]):
            raise ValueError(f"{self.csv_path}: not a {type(self).__name__} of this version "
                             "(header differs); use another --out folder")
        parsed: dict[str, dict[str, Any]] = {}
        for line in lines[1:]:
            try:
                fields = next(csv.reader([line]))
                if len(fields) != len(self.columns):
                    continue
                row = {c: _parse(c, v, self.text_columns) for c, v in zip(self.columns, fields)}
            except (csv.Error, StopIteration, ValueError):
                continue
            parsed.pop(row["key"], None)      # a repeated key: the newest row, at its place
            parsed[row["key"]] = row
        rows = self.derive(list(parsed.values()))
        if repair and self._text(rows) != text:
            atomic_write(self.csv_path, self._text(rows))
        if repair and rows and not self._parquet_holds(rows):
            self._write_parquet(rows)
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
        """Add one finished point, re-derive every row, update both files.

        A row whose key is already present replaces it (a retried error). Returns the new
        row as stored (derived columns filled).
        """
        new = self._full(row)
        old = [r for r in self.rows if r["key"] != new["key"]]
        rows = self.derive([*old, new])
        if self.csv_path.exists() and len(old) == len(self.rows) and \
                all(_same(a, b, self.columns) for a, b in zip(self.rows, rows)):
            with open(self.csv_path, "a", encoding="utf-8") as fh:
                fh.write(_line(rows[-1], self.columns))
                fh.flush()
                os.fsync(fh.fileno())
        else:   # a new file, a replaced row, or rows whose verdict depends on the new one
            atomic_write(self.csv_path, self._text(rows))
        self.rows = rows
        self._write_parquet(rows)
        return rows[-1]

    def _write_parquet(self, rows: Sequence[Mapping[str, Any]]) -> Path:
        import pyarrow as pa
        import pyarrow.parquet as pq

        cols = {c: pa.array([r[c] for r in rows], type=pa.string() if c in self.text_columns
                            else pa.float64()) for c in self.columns}
        buf = pa.BufferOutputStream()
        pq.write_table(pa.table(cols), buf)
        atomic_write(self.parquet_path, buf.getvalue().to_pybytes())
        return self.parquet_path

    def _parquet_holds(self, rows: Sequence[Mapping[str, Any]]) -> bool:
        """Does ``results.parquet`` hold exactly ``rows`` (same order)?"""
        if not self.parquet_path.exists():
            return False
        import pyarrow.parquet as pq

        try:
            saved = pq.read_table(self.parquet_path).to_pylist()
        except Exception:  # noqa: BLE001 - unreadable (e.g. cut by a kill): rewrite it
            return False
        return len(saved) == len(rows) and all(_same(a, b, self.columns)
                                               for a, b in zip(saved, rows))


def read_table(folder_or_file: str | os.PathLike) -> list[dict[str, Any]]:
    """Rows of a sweep (folder, ``results.csv`` or ``results.parquet``), derived columns filled.

    A folder or CSV is read as a :class:`ResultTable` (rows re-derived; nothing is written).
    """
    p = Path(folder_or_file)
    if p.suffix == ".parquet":
        import pyarrow.parquet as pq

        return pq.read_table(p).to_pylist()
    return ResultTable(p.parent if p.suffix == ".csv" else p).rows


def rows_csv(rows: Sequence[Mapping[str, Any]]) -> str:
    """CSV text of dict rows (the first row's keys as columns; NaN empty, floats by repr)."""
    if not rows:
        return ""
    cols = list(rows[0])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow(["" if isinstance(r[c], float) and math.isnan(r[c]) else
                    (repr(r[c]) if isinstance(r[c], float) else r[c]) for c in cols])
    return buf.getvalue()
