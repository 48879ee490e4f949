"""One BLAS thread for the plant's small dense eigenproblems (threadpoolctl, optional).

``threadpool_limits(1)`` around an eigenvalue problem of a few hundred states is several times
faster than multithreaded BLAS on a loaded machine. threadpoolctl is optional: the plant FMU
must also run in a host Python without it, where the call does nothing.
"""

from __future__ import annotations

try:  # optional: the plant FMU must also run in a host Python without it
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover
    from contextlib import nullcontext

    def threadpool_limits(limits: int):  # noqa: D103 - same call shape, no effect
        return nullcontext()

__all__ = ["threadpool_limits"]
