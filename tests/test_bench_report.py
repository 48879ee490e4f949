"""``drillcosim bench`` (benchmarks/run_all.py) rewrites only what it generates.

The report (BENCHMARKS.md) is written whole by the bench; the hand-written performance log
(docs/performance.md) is never written by it. Here the report is generated with the measuring
functions replaced by stand-ins of their results' shape (the benchmarks themselves take 10-40
min): the files written are the report and the results folder given, nothing in the checkout
changes, and every section heading of the committed BENCHMARKS.md is one the bench makes (no
hand-written section that the next run would erase).
"""

from __future__ import annotations

import hashlib
import importlib.util
import re
from pathlib import Path
from types import SimpleNamespace

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"


@pytest.fixture(scope="module")
def run_all():
    spec = importlib.util.spec_from_file_location("dcs_bench_run_all", BENCH / "run_all.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _runs(labels: list[str], family: str = "rk4") -> list[SimpleNamespace]:
    return [SimpleNamespace(label=lab, family="naive" if lab.startswith("naive") else family,
                            wall=0.1 * (i + 1), nfev=None, ok=True) for i, lab in enumerate(labels)]


def _stand_ins(monkeypatch, run_all) -> None:
    """The measuring functions' results, in shape (the numbers mean nothing)."""
    model = SimpleNamespace(n=30)
    wp_3d = {"runs": _runs(["rk4 (auto step h*)", "dopri5 rtol 1e-08", "naive rk45"]),
             "errors": [1e-6, 1e-9, 1e-6], "T": 2.0, "model": model,
             "ref": SimpleNamespace(label="ref"), "ref_wall": 1.0, "ref_check": 1e-12,
             "h_star": 4e-4, "rhs_call": {"numba": 5e-6, "numpy": 4e-4}}
    wp_at = {**wp_3d, "runs": _runs(["expeuler h = 1 ms", "rk4 (auto step h*)"]),
             "errors": [1e-9, 1e-8], "default_label": "expeuler",
             "kernel_wall": {"rk4": 0.01, "expeuler": 0.005}}
    stats = {"rms body11": 1e-3}
    long_run = {"runs": _runs(["rk4 (auto step h*)"]), "stats": [stats], "T": 30.0,
                "contact_seen": True, "ref": SimpleNamespace(label="ref"),
                "ref_check": {"rms body11": 1e-4}, "traj2": [1e-6],
                "rms_ref": {"body11": 1e-2}, "peak_ref": {"body11": 2e-2}}
    rt = {k: {"T": 10.0, "rtf": 500.0, "wall": 0.02, "method": "expeuler"}
          for k in ("3d", "at auto", "at torsional auto", "at rk4")}
    monkeypatch.setattr(run_all.wp, "work_precision_3d", lambda quick: wp_3d)
    monkeypatch.setattr(run_all.wp, "work_precision_at", lambda quick: wp_at)
    monkeypatch.setattr(run_all.wp, "long_run_stats", lambda quick: long_run)
    monkeypatch.setattr(run_all.bs, "real_time", lambda quick: rt)
    monkeypatch.setattr(run_all.bs, "scaling_n", lambda quick: {
        "n": [15, 30], "h_star": [8e-4, 4e-4], "wall": [0.1, 0.4], "T": 2.0,
        "exponent": 2.0, "exponent_large": 2.0})
    monkeypatch.setattr(run_all.bs, "scaling_time", lambda quick: {
        "T": [1.0, 2.0], "wall": [0.1, 0.2], "exponent": 1.0})
    kb = {"maxrss_kb": 2e5, "tracemalloc_peak_b": 3e6}
    monkeypatch.setattr(run_all.bs, "memory", lambda quick: {
        "T": 30.0, "run": kb, "imports+model": kb, "cold": kb})
    monkeypatch.setattr(run_all, "_script", lambda args, timeout: "")


def _digest(folder: Path) -> dict[str, str]:
    skip = (".git", ".venv", "build", "out", "__pycache__", ".pytest_cache", ".ruff_cache",
            ".hypothesis")
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in folder.rglob("*") if p.is_file()
            and not any(part in skip or part.endswith(".egg-info")
                        for part in p.relative_to(folder).parts)}


def test_the_bench_writes_its_report_and_results_only(run_all, monkeypatch, tmp_path) -> None:
    _stand_ins(monkeypatch, run_all)
    before = _digest(ROOT)
    out, results = tmp_path / "BENCHMARKS.md", tmp_path / "results"
    text = run_all.report(True, out, results)
    assert _digest(ROOT) == before  # the checkout: BENCHMARKS.md, docs/performance.md untouched
    assert out.read_text() == text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["BENCHMARKS.md", "results"]
    assert sorted(p.name for p in results.iterdir()) == [
        "work_precision_axial_torsional.png", "work_precision_full3d.png"]
    assert run_all.LOG_NOTE in text and "docs/performance.md" in run_all.LOG_NOTE


def _headings(text: str) -> list[str]:
    return re.findall(r"^(#{2,4} .+)$", text, flags=re.M)


def test_every_section_of_the_committed_report_is_generated() -> None:
    """Each heading of BENCHMARKS.md begins as one that run_all.py or a benchmark script writes
    (its text up to the first parenthesis or colon, which the run fills in)."""
    sources = "\n".join(p.read_text() for p in BENCH.glob("*.py"))

    def stem(heading: str) -> str:
        text = re.sub(r"^#+ (\d+\. )?", "", heading)
        return re.split(r"[(:]", text, maxsplit=1)[0].strip()

    committed = (ROOT / "BENCHMARKS.md").read_text()
    assert run_all_note_in(committed)
    for heading in _headings(committed):
        assert stem(heading) and stem(heading) in sources, heading
    # the hand-written log is elsewhere, and points back at the report
    log = (ROOT / "docs" / "performance.md").read_text()
    assert "BENCHMARKS.md" in log and "never writes this file" in log


def run_all_note_in(text: str) -> bool:
    return "docs/performance.md" in text and "writes this file whole" in text
