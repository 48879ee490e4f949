"""Self-contained FMUs on Windows: the plant + controller pair with their win64 runtimes (the
embeddable CPython 3.13 and the wheels) in a plain C host built with mingw-w64, under wine,
with no Python on PATH or WINEPATH (the controller's runtime joins the plant's): equal to the
same host's Linux run (CPython 3.11, other numpy/scipy builds) to 1e-12 of each signal's peak.

The Windows bench (wine, mingw-w64, the embeddable CPython and the wheels) is
``support/windows_bench.py``: under CI a missing piece fails the test; elsewhere it skips with
one line naming what is missing.
"""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

from support import c_host, cosim_host
from support.closed_loop import closed_loop
from support.standalone import bare_env, standalone_copy

pytestmark = [pytest.mark.needs_cc, pytest.mark.interop, pytest.mark.slow]

STOP = 0.02  #: [s] (200 steps of 0.1 ms: numba compiles the plant under wine once per cache)


@pytest.fixture(scope="module")
def bench():
    """The prepared bench; the win64 runtime's wheels are taken from its persistent downloads
    (``$DRILLCOSIM_WIN64_DOWNLOADS``, unless set)."""
    from support import windows_bench

    found = windows_bench.require()
    wheels = windows_bench.bench_dir() / "downloads" / "win_amd64-cp313"
    with pytest.MonkeyPatch.context() as mp:
        if not os.environ.get("DRILLCOSIM_WIN64_DOWNLOADS"):
            mp.setenv("DRILLCOSIM_WIN64_DOWNLOADS", str(wheels))
        yield found


def test_the_standalone_pair_runs_under_wine_with_no_python_equal_to_linux(
        bench, windows_caches, project_fmus, tmp_path) -> None:
    from support import windows_bench

    loop = closed_loop(project_fmus["DrillstringPlant"], project_fmus["StrainController"],
                       tmp_path / "loop", stop=STOP)
    win, lin = {}, {}
    for inst, name in (("plant", "DrillstringPlant"), ("controller", "StrainController")):
        fmu = standalone_copy(project_fmus[name], ("win64",))
        win[inst] = windows_bench.windows_path(c_host.unzip(fmu, tmp_path / inst))
        lin[inst] = str(c_host.unzip(project_fmus[name], tmp_path / f"{inst}-linux"))
    # the Linux run: the same host on the regular FMUs with this Python (bit for bit the
    # self-contained linux64 ones' run: test_standalone.py)
    host = cosim_host.compile_host(tmp_path)
    spec = cosim_host.write_spec(loop, lin, tmp_path / "linux.spec")
    linux = cosim_host.run([str(host), str(spec)],
                           bare_env(tmp_path / "home", DRILLCOSIM_PYTHON=sys.executable),
                           tmp_path)
    assert linux.returncode == 0, linux.stderr[-3000:]
    # under wine: the mingw-built host, no Python on PATH / WINEPATH
    exe = cosim_host.compile_host(tmp_path, cc=windows_bench.find_mingw())
    spec = cosim_host.write_spec(loop, win, tmp_path / "win.spec")
    out = tmp_path / "win.csv"
    env = bench.env({"WINEPATH": "", "DRILLCOSIM_PYTHON": "", **windows_caches})
    code, text, log = cosim_host.run_to_file(
        [bench.wine, str(exe), windows_bench.windows_path(spec), windows_bench.windows_path(out)],
        out, env, tmp_path)
    assert code == 0, log[-3000:]
    assert "the FMU's own Python runtime (Python 3.13" in log
    assert "joins the one running" in log
    rows_win, rows_linux = cosim_host.rows(text), cosim_host.rows(linux.stdout)
    assert rows_win.shape == rows_linux.shape == (loop.n_steps + 1, len(loop.outputs) + 1)
    peak = np.max(np.abs(rows_linux), axis=0)
    worst = np.max(np.abs(rows_win - rows_linux) - 1e-12 * peak, axis=0)
    assert (worst <= 0).all(), {loop.outputs[j - 1]: float(np.max(np.abs(
        rows_win[:, j] - rows_linux[:, j])) / peak[j]) for j in np.flatnonzero(worst > 0)}
