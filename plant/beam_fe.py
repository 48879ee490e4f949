"""Euler-Bernoulli beam finite elements (Hermite cubics): an independent lateral reference.

Used to set the lateral damping reference frequency of the support layout, and by the tests as a
second implementation next to the closed-form beam formulas.
"""

from __future__ import annotations

import numpy as np

__all__ = ["pinned_beam_frequencies"]


def pinned_beam_frequencies(
    length: float,
    supports: np.ndarray | list[float],
    ei: float,
    rho_a: float,
    n_elements: int = 240,
    axial_tension: float = 0.0,
    count: int = 3,
) -> np.ndarray:
    """Lowest bending natural frequencies [rad/s] of a beam on pinned supports.

    Parameters
    ----------
    length : float
        Beam length [m]; coordinate s runs from 0 to ``length``.
    supports : array_like, shape (k,)
        Coordinates [m] of the pinned (zero deflection, free rotation) supports, k >= 2.
    ei : float
        Bending stiffness E I [N m^2].
    rho_a : float
        Mass per length rho A [kg/m].
    n_elements : int
        Number of elements of the uniform part of the mesh (supports are added as nodes).
    axial_tension : float
        Uniform axial tension P [N] (negative = compression), via the geometric stiffness.
    count : int
        How many frequencies to return.

    Returns
    -------
    numpy.ndarray, shape (count,)
        Natural frequencies [rad/s], ascending.
    """
    sup = np.asarray(supports, dtype=float)
    grid = np.linspace(0.0, length, n_elements + 1)
    # drop grid nodes within a quarter element of a support: no degenerate short elements
    near = np.min(np.abs(grid[:, None] - sup[None, :]), axis=1) < 0.25 * length / n_elements
    nodes = np.unique(np.concatenate([grid[~near], sup]))
    ne = nodes.size - 1
    ndof = 2 * nodes.size
    K = np.zeros((ndof, ndof))
    M = np.zeros((ndof, ndof))
    for e in range(ne):
        le = nodes[e + 1] - nodes[e]
        ke = ei / le**3 * np.array(
            [
                [12, 6 * le, -12, 6 * le],
                [6 * le, 4 * le**2, -6 * le, 2 * le**2],
                [-12, -6 * le, 12, -6 * le],
                [6 * le, 2 * le**2, -6 * le, 4 * le**2],
            ]
        )
        kg = axial_tension / (30.0 * le) * np.array(
            [
                [36, 3 * le, -36, 3 * le],
                [3 * le, 4 * le**2, -3 * le, -(le**2)],
                [-36, -3 * le, 36, -3 * le],
                [3 * le, -(le**2), -3 * le, 4 * le**2],
            ]
        )
        me = rho_a * le / 420.0 * np.array(
            [
                [156, 22 * le, 54, -13 * le],
                [22 * le, 4 * le**2, 13 * le, -3 * le**2],
                [54, 13 * le, 156, -22 * le],
                [-13 * le, -3 * le**2, -22 * le, 4 * le**2],
            ]
        )
        idx = np.arange(2 * e, 2 * e + 4)
        K[np.ix_(idx, idx)] += ke + kg
        M[np.ix_(idx, idx)] += me
    fixed = [2 * int(np.argmin(np.abs(nodes - s))) for s in sup]
    free = np.setdiff1d(np.arange(ndof), fixed)
    return np.sqrt(np.maximum(_generalized_eigvalsh(K[np.ix_(free, free)],
                                                    M[np.ix_(free, free)])[:count], 0.0))


def _generalized_eigvalsh(k: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Eigenvalues, ascending, of the symmetric pencil k v = w m v with m positive definite.

    Reduced to a standard symmetric problem through the Cholesky factor m = L L^T
    (L^-1 k L^-T), in numpy alone: the plant builds this at every start, and scipy.linalg's
    import would cost more than the solve (scipy's ``eigh(k, m)`` agrees to ~1e-10 relative;
    tests/test_plant_physics.py checks the frequencies against the closed-form beams).
    """
    chol = np.linalg.cholesky(m)
    half = np.linalg.solve(chol, k)
    a = np.linalg.solve(chol, half.T)
    return np.linalg.eigvalsh(0.5 * (a + a.T))
