"""StrainController.fmu in a third-party FMI engine: libcosim (via libcosimpy).

Run in a subprocess: libcosim loads the FMU in process and logs verbosely to
stderr; a crash there must not take pytest down.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from support.required import import_module

pytestmark = [pytest.mark.interop]

import_module("libcosimpy")

SCRIPT = textwrap.dedent("""
    import json, sys
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    fmu, n_steps = sys.argv[1], int(sys.argv[2])
    ex = CosimExecution.from_step_size(step_size=1_000_000)  # nanoseconds: 1 ms
    slave = CosimLocalSlave(fmu_path=fmu, instance_name="ctl")
    idx = ex.add_local_slave(local_slave=slave)
    vr = {v.name.decode(): v.reference for v in ex.slave_variables(idx)}
    obs = CosimObserver.create_last_value()
    ex.add_observer(observer=obs)
    ex.real_initial_value(idx, vr["strain1_C"], 2e-6)
    ex.real_initial_value(idx, vr["strain2_E"], -1e-6)
    ex.real_initial_value(idx, vr["lag_time_constant"], 0.05)
    ex.integer_initial_value(idx, vr["mode"], 1)
    ok = ex.step(n_steps)
    forces = obs.last_real_values(idx, [vr[n] for n in (
        "actuator1_force_C", "actuator1_force_E", "actuator2_force_C", "actuator2_force_E")])
    print("RESULT " + json.dumps({"ok": bool(ok), "forces": list(forces)}), flush=True)
""")


def test_libcosim_runs_the_controller_fmu(tmp_path: Path, project_fmus: dict[str, Path]) -> None:
    fmu = project_fmus["StrainController"]
    script = tmp_path / "cosim_host.py"
    script.write_text(SCRIPT)
    n_steps = 100
    proc = subprocess.run([sys.executable, str(script), str(fmu), str(n_steps)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert result, proc.stdout[-3000:]
    out = json.loads(result[-1].removeprefix("RESULT "))
    assert out["ok"]
    lag = 1.0 - math.exp(-n_steps * 1e-3 / 0.05)
    f1c, f1e, f2c, f2e = out["forces"]
    assert f1c == pytest.approx(2000.0 * lag, rel=1e-12)
    assert (f1e, f2c, f2e) == (0.0, 0.0, 0.0)  # compressive_only: negative strain -> 0
