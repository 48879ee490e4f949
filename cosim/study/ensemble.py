"""Ensembles of perturbed runs: statistics of chaotic trajectories.

The lateral whirl of the paper scenes is chaotic once the string rubs the wall: two runs whose
initial states differ by 1e-6 m part after ~15 s, so a statistic of ONE 30 s run is one sample
of a random variable. An ensemble member is the same scene started from the initial state plus
:func:`lateral_perturbation` (``benchmarks/bench_rms_sensitivity.py`` measured the approach:
1e-6 m decorrelates the members within 30 s, 1e-9 m does not). Member 0 is unperturbed, so it
is the run ``drillcosim run`` makes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

__all__ = ["EnsembleStat", "ensemble_stat", "lateral_indices", "lateral_perturbation"]


def lateral_indices(model) -> np.ndarray:
    """Indices of the lateral positions X, Y of every body in the plant state.

    Parameters
    ----------
    model : plant.model.DrillstringModel
        Full 3D model (state: positions X, Y, Z body by body first).

    Returns
    -------
    numpy.ndarray of int, shape (2 n,)
        ``[X_1, Y_1, X_2, Y_2, ...]``.
    """
    if model.kind != "full3d":
        raise ValueError(f"the ensemble needs the full 3D model, got {model.kind!r}")
    first = 3 * np.arange(model.n)
    return np.column_stack([first, first + 1]).ravel()


def lateral_perturbation(model, eps: float, seed: int, member: int) -> np.ndarray:
    """Seeded Gaussian perturbation (std ``eps`` [m]) of the lateral positions of all bodies.

    Parameters
    ----------
    model : plant.model.DrillstringModel
        Full 3D model.
    eps : float
        Standard deviation [m], >= 0.
    seed, member : int
        The stream is ``numpy.random.default_rng([seed, member])``: a member is reproducible
        on its own. Member 0 is the unperturbed state (zeros) whatever ``eps``.

    Returns
    -------
    numpy.ndarray, shape (model.n_state,)
        The offset of the initial state [m in the X, Y entries, 0 elsewhere].
    """
    if not (math.isfinite(eps) and eps >= 0):
        raise ValueError(f"eps = {eps!r}: a finite standard deviation >= 0 [m]")
    if member < 0:
        raise ValueError(f"member = {member!r}: >= 0")
    lat = lateral_indices(model)
    dy = np.zeros(model.n_state)
    if member > 0 and eps > 0:
        dy[lat] = eps * np.random.default_rng([seed, member]).standard_normal(lat.size)
    return dy


class EnsembleStat(NamedTuple):
    """A statistic over the members: NaN where undefined (no finite value, or one)."""

    mean: float
    sd: float           #: sample standard deviation (ddof 1)
    se: float           #: standard error of the mean, sd / sqrt(n)
    n: int              #: members with a finite value


def ensemble_stat(values: Sequence[float]) -> EnsembleStat:
    """:class:`EnsembleStat` of the finite entries of ``values``."""
    x = np.asarray([v for v in values if isinstance(v, (int, float)) and math.isfinite(v)],
                   dtype=float)
    if x.size == 0:
        return EnsembleStat(math.nan, math.nan, math.nan, 0)
    if x.size == 1:
        return EnsembleStat(float(x[0]), math.nan, math.nan, 1)
    sd = float(np.std(x, ddof=1))
    return EnsembleStat(float(x.mean()), sd, sd / math.sqrt(x.size), int(x.size))
