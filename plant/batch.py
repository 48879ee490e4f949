"""A compiled run-and-record loop: many output steps without returning to Python.

For plant-alone runs (benchmarks, studies) the Python cost of one ``PlantSimulator.do_step``
(~5 us) is comparable to the physics of a 1 ms step of the axial-torsional chain; this loop does
the same internal steps, outputs and validity checks as ``PlantSimulator.do_step`` +
``outputs()`` in one compiled call, bit for bit.
"""

from __future__ import annotations

from numba import njit

from .guards import OK, check_state
from .integrators import advance_expeuler, advance_rk4_span
from .kernels import MODEL_FULL3D
from .observables import outputs3d, outputs_at

RECORD_RK4 = 0
RECORD_EXPEULER = 1


@njit(cache=True)
def run_record(model, method, t0, h, n_out, max_dt, breakpoints, y, p, ip, fp, u, wR, wF, wM, k1,
               k2, k3, k4, yt, op_idx, op_sizes, op_blocks, op_ramp, zbit_ref, out, idx, rec,
               limits):
    """Advance ``n_out`` output steps of ``h`` [s], recording the outputs ``idx``.

    ``method``: :data:`RECORD_RK4` (steps <= ``max_dt`` [s], split at ``breakpoints`` by
    :func:`plant.integrators.advance_rk4_span`) or :data:`RECORD_EXPEULER` (one exponential
    Euler step of ``h`` with the operator ``op_*`` for this ``h``,
    ``DrillstringModel.expeuler_operator``; the caller ensures that no breakpoint lies inside
    an output step). ``rec`` (n_out + 1, len(idx)) receives the outputs
    at t0 and after every step; ``limits`` = (max_lateral, max_tilt, max_speed, max_strain).
    Returns ``(completed output steps, guard code, index, value)``; on a violation the row of
    the failing step is recorded and the loop stops.
    """
    full3d = model == MODEL_FULL3D
    n = ip[0]
    if full3d:
        outputs3d(t0, y, p, ip, fp, u, wR, zbit_ref, out)
    else:
        outputs_at(t0, y, p, ip, fp, u, wR, zbit_ref, out)
    for j in range(idx.size):
        rec[0, j] = out[idx[j]]
    for k in range(n_out):
        t = t0 + k * h
        if method == RECORD_EXPEULER:
            advance_expeuler(model, t, y, 1, h, op_idx, op_sizes, op_blocks, op_ramp, p, ip,
                             fp, u, wR, wF, wM, k1, k2)
        else:
            advance_rk4_span(model, t, t + h, max_dt, breakpoints, y, p, ip, fp, u, wR, wF, wM,
                             k1, k2, k3, k4, yt)
        code, i, val = check_state(full3d, n, y, limits[0], limits[1], limits[2], limits[3],
                                   wR, p, ip)
        if full3d:
            outputs3d(t + h, y, p, ip, fp, u, wR, zbit_ref, out)
        else:
            outputs_at(t + h, y, p, ip, fp, u, wR, zbit_ref, out)
        for j in range(idx.size):
            rec[k + 1, j] = out[idx[j]]
        if code != OK:
            return k + 1, code, i, val
    return n_out, OK, -1, 0.0
