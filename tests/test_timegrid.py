"""One authority for time: integer ticks and one on-grid rule (``cosim/master/timegrid.py``).

The rule is checked against exact decimal arithmetic; a search of the layers that decide time
(config, master, execution, delays, the state-space check, the sweep's grid) finds no second
rule: no ``Fraction`` arithmetic of its own, no hand-written "ratio near an integer" test.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal
from pathlib import Path

import pytest

from drillcosim.controller.state_space import MULTIPLE_RTOL
from drillcosim.cosim.master import timegrid
from drillcosim.cosim.master.delays import DelayLine
from drillcosim.cosim.scenario.config import load_config

ROOT = Path(__file__).resolve().parents[1]
#: Where time is decided (the study's physics and figures round lengths and frequencies, not
#: times on the grid).
SEARCHED = [*(ROOT / "cosim" / "master").rglob("*.py"), *(ROOT / "cosim" / "scenario").rglob("*.py"),
            *(ROOT / "drillcosim").glob("*.py"),
            *(ROOT / "cosim" / "study" / n for n in ("grid.py", "sweep.py", "point.py"))]
#: A second rule: exact-fraction arithmetic, or "is this ratio an integer" written by hand.
SECOND_RULE = re.compile(
    r"\bFraction\(|limit_denominator"                     # tick <-> seconds arithmetic
    r"|abs\(\s*[\w.]+\s*-\s*round\("                       # abs(k - round(k)) > tol
    r"|abs\(\s*\w+\s*-\s*\w+\s*\)\s*>\s*[\w.+-]+\s*\*\s*max\("  # abs(ratio - n) > tol * max
    r"|abs\([^()]*\*\s*\w+\s*-\s*\w+\s*\)\s*>"             # abs(n * H - interval) > tol
    r"|floor\([^()]*\+\s*_?EPS|ceil\([^()]*-\s*1e-9"       # floor(ratio + EPS), ceil(x - 1e-9)
    r"|MULTIPLE_RTOL")


@pytest.mark.parametrize("seconds, step, ticks", [
    (30.0, 2.5e-4, 120000), (0.1, 2.5e-4, 400), (1e-3, 1e-4, 10), (0.0, 1e-3, 0),
    (3e-3, 1e-3, 3), (1e-3, 3e-4, None), (-1e-3, 1e-3, None), (math.nan, 1e-3, None),
    (math.inf, 1e-3, None), (1e-3 * (1 + 1e-6), 1e-3, None)])
def test_the_rule_is_exact_decimal_arithmetic(seconds, step, ticks) -> None:
    """On the grid iff the decimal quotient is a whole number (the float inputs are decimal
    literals, so their exact decimal values decide)."""
    assert timegrid.grid_ticks(seconds, step) == ticks
    assert timegrid.on_grid(seconds, step) == (ticks is not None)
    assert timegrid.integer_multiple(seconds, step) == (ticks or None)
    if ticks is not None and math.isfinite(seconds):
        q = Decimal(repr(seconds)) / Decimal(repr(step))
        assert q == q.to_integral_value() == ticks


@pytest.mark.parametrize("ticks, step", [(120000, 2.5e-4), (7, 0.1), (3, 1 / 3), (10**9, 1e-5)])
def test_seconds_are_the_exact_product_rounded_once(ticks, step) -> None:
    want = float(Decimal(repr(step)) * ticks) if step != 1 / 3 else 1.0
    assert timegrid.seconds(ticks, step) == want
    assert timegrid.seconds(ticks, step, 2.0) == 2.0 + want


def test_a_delay_line_splits_by_the_rule() -> None:
    """On the grid: whole samples, no interpolation; off it: floor and the fraction."""
    on = DelayLine(1e-3, 2.5e-4)
    assert (on.n, on.f) == (4, 0.0)
    off = DelayLine(1e-3, 3e-4)
    assert off.n == 3 and off.f == pytest.approx(1 / 3, rel=1e-12)


def test_config_and_the_state_space_law_use_the_same_rule() -> None:
    cfg = load_config("paper_closed_loop", {"cosim.step": 2.5e-4, "cosim.stop_time": 0.1})
    assert cfg.cosim.stop_ticks == timegrid.grid_ticks(0.1, 2.5e-4) == 400
    assert cfg.cosim.stop_time == 0.1 and cfg.cosim.output_ticks == 4
    # the state-space FMU's own check (controller/, vendored apart) has the master's tolerance
    assert MULTIPLE_RTOL == timegrid.RTOL


def test_there_is_one_on_grid_rule() -> None:
    found = []
    for path in SEARCHED:
        if path.name == "timegrid.py" or "__pycache__" in path.parts:
            continue
        for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            if SECOND_RULE.search(line.split("#", 1)[0]):
                found.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert not found, "\n".join(found)


def test_the_search_finds_the_rules_it_replaced() -> None:
    """The five rules of before (master/system.py, master.py, execution.py, delays.py,
    config.py) and the state-space check, as they were written."""
    for old in ("    if n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):",
                "if interval < 1 or abs(interval * H - output_interval) > 1e-9 * output_interval:",
                "        if abs(exact - k) > Fraction(1, 10**6):",
                "        n = math.floor(ratio + _EPS)",
                "        frac = Fraction(self.step).limit_denominator(10**12)",
                "        output_ticks = max(1, math.ceil(1e-3 / step - 1e-9))",
                "    if abs(k - round(k)) > MULTIPLE_RTOL * max(1.0, k) or round(k) < 1:"):
        assert SECOND_RULE.search(old), old
    for fine in ("n = grid_ticks(seconds, step)", "span = round(t / h)", "x = abs(a - b)"):
        assert not SECOND_RULE.search(fine), fine
