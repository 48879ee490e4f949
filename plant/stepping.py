"""Stepping the plant (one job: integration and the method choice).

:class:`Stepping` is the part of :class:`plant.model.DrillstringModel` that advances a state:
the fixed-step methods of :data:`plant.integrators.METHODS` over the model's arrays, the
adaptive Dormand-Prince method, the exponential integrators' operators (from the Jacobian at
the initial state, cached per step size), the spectral radius behind every stable step, and the
automatic choice of a method for a communication step (:meth:`Stepping.method_for_step`).
"""

from __future__ import annotations

import hashlib
import math
from functools import cached_property

import numpy as np

from . import kernels as kern
from . import layout as lay
from .blas import threadpool_limits
from .integrators import (
    KERNEL_ERK,
    KERNEL_ETD2,
    KERNEL_EXPEULER,
    KERNEL_RK4,
    KERNEL_VERLET,
    METHODS,
    advance_dopri5,
    advance_erk,
    advance_etd2,
    advance_expeuler,
    advance_rk4,
    advance_rk4_span,
    advance_verlet,
    block_split,
    exponential_matrices,
    polynomial_input_responses,
    stable_step,
)
from .params import PlantParams

__all__ = ["FIXED_STEP_METHODS", "SPECTRAL_RADII", "Stepping", "spectral_key"]

# exponential-integrator matrices kept per step size (each costs one expm, ~10 ms at n = 30)
_EXPM_CACHE_SIZE = 8
# Fixed-step methods of :meth:`DrillstringModel.advance` and their stability radius |lambda dt|
# (None: no stability limit; exponential integrators treat the linear part exactly; 0: none
# automatic). The table itself: :data:`plant.integrators.METHODS`.
FIXED_STEP_METHODS = {name: m.radius for name, m in METHODS.items()}
#: Spectral radius [1/s] (with margins) of every (parameters, model kind) built in this process,
#: by :func:`spectral_key`: it costs a Jacobian (2 n_state right-hand sides) and an eigenvalue
#: problem (~50 ms for 30 bodies) that another model of the same parameters (a second FMU
#: instance, a sweep point, a re-run) need not repeat. A pure function of the key, so results
#: are unchanged; a caller may fill it from a store of its own (the plant FMU keeps one beside
#: its stable copy, per numpy version).
SPECTRAL_RADII: dict[str, float] = {}


def spectral_key(params: PlantParams, kind: str) -> str:
    """Key of :data:`SPECTRAL_RADII`: SHA-256 (hex) of ``repr((params, kind))`` (the frozen
    parameter tree's repr is complete: floats round-trip, strings are quoted)."""
    return hashlib.sha256(repr((params, kind)).encode()).hexdigest()


class Stepping:
    """Mixin of :class:`plant.model.DrillstringModel`: advancing a state and choosing how.

    Uses the model's ``params``, ``kind``, ``model_id``, ``bodies``, ``n``, ``n_state``,
    ``n_body_state``, ``aux_names``, its arrays (``p``, ``ip``, ``fp``, ``breakpoints``, ``u``,
    the scratch ``work``, ``wR``, ``wF``, ``wM``), :meth:`rhs` and :meth:`initial_state`.
    """

    def jacobian(self, t: float, y: np.ndarray, rel_step: float = 1e-7) -> np.ndarray:
        """Central finite-difference Jacobian of :meth:`rhs`; shape (n_state, n_state)."""
        N = self.n_state
        J = np.empty((N, N))
        yp = y.copy()
        for i in range(N):
            h = rel_step * max(1.0, abs(y[i]))
            yp[i] = y[i] + h
            fp = self.rhs(t, yp)
            yp[i] = y[i] - h
            fm = self.rhs(t, yp)
            yp[i] = y[i]
            J[:, i] = (fp - fm) / (2.0 * h)
        return J

    @cached_property
    def initial_jacobian(self) -> np.ndarray:
        """Jacobian of the rhs at t = 0 and the initial (static equilibrium) state [1/s].

        Shape (n_state, n_state); the step choice and the exponential integrators share it.
        """
        return self.jacobian(0.0, self.initial_state())

    @cached_property
    def max_eigenvalue(self) -> float:
        """Spectral radius [1/s] of the Jacobian at the initial state, plus active-contact margin.

        Contact adds at most k_w/m to the squared frequency of one body; that margin is added so
        that the step stays stable when the pipe touches the wellbore. Computed once per
        parameter set and model kind in a process.
        """
        key = spectral_key(self.params, self.kind)
        if key not in SPECTRAL_RADII:
            SPECTRAL_RADII[key] = self.spectral_radius_with_margins(self.initial_jacobian)
        return SPECTRAL_RADII[key]

    def spectral_radius_with_margins(self, J: np.ndarray) -> float:
        """Spectral radius [1/s] of ``J`` (a Jacobian of this model, possibly augmented) plus
        the margins of :attr:`max_eigenvalue` for effects the initial state does not show."""
        with threadpool_limits(1):  # 6x faster than multithreaded BLAS on a loaded machine
            lam = float(np.max(np.abs(np.linalg.eigvals(J))))
        touching = self.ip[kern.IP_NCP] > 0 and self.kind == "full3d"
        kc = self.p[lay.K_CONT] if touching else 0.0
        cc = self.p[lay.C_CONT] if touching else 0.0
        m = float(self.bodies.mass[self._contact_point_bodies()].min()) if touching else 1.0
        return math.sqrt(lam**2 + kc / m) + cc / m

    def _contact_point_bodies(self) -> np.ndarray:
        """0-based body of every contact point (rows of the contact-point table)."""
        ncp = int(self.ip[kern.IP_NCP])
        o = self.ip[kern.IP_NS] + lay.NLD * self.ip[kern.IP_NL]
        return self.fp[o + lay.CP_BODY: o + lay.NCP * ncp: lay.NCP].astype(np.int64)

    def stable_step(self) -> float:
        """Largest stable RK4 step [s] for this model (from :attr:`max_eigenvalue`)."""
        return stable_step(self.max_eigenvalue)

    def advance(self, t0: float, y: np.ndarray, n_steps: int, dt: float,
                u: np.ndarray | None = None, method: str = "rk4") -> int:
        """Integrate ``y`` in place over ``n_steps`` fixed steps of ``dt`` [s] from ``t0`` [s].

        ``method``: a fixed-step method of :data:`plant.integrators.METHODS`: ``"rk4"``
        (default), explicit Runge-Kutta methods of fewer stages (``"kutta3"``, ...),
        ``"verlet"`` (velocity Verlet, 1 rhs a step), ``"expeuler"`` / ``"etd2"``
        (exponential integrators about the equilibrium Jacobian, axial-torsional model only).
        Returns the number of completed steps before a non-finite state (``n_steps`` if
        none). Step loads switch once a step (at its midpoint): a step that straddles a
        switch time sees one value; :meth:`advance_span` and ``PlantSimulator`` split the steps
        at :attr:`breakpoints`.
        """
        k1, k2, k3, k4, yt = self._scratch
        uu = self.u if u is None else u
        a = (self.model_id, float(t0), y, int(n_steps), float(dt))
        w = (self.p, self.ip, self.fp, uu, self.wR, self.wF, self.wM)
        spec = METHODS.get(method)
        kernel = spec.kernel if spec is not None else -1
        if kernel == KERNEL_RK4:
            return int(advance_rk4(*a, *w, k1, k2, k3, k4, yt))
        if kernel == KERNEL_ERK:
            A, b, c = spec.tableau
            return int(advance_erk(*a, A, b, c, self.work[:4], yt, *w))
        if kernel == KERNEL_VERLET:
            if self.n_state != self.n_body_state:
                raise ValueError(f"method = 'verlet' needs a state of positions and velocities; "
                                 f"this model has the first-order states {self.aux_names}: use "
                                 "'rk4'")
            H = self.n_state // 2
            return int(advance_verlet(*a, self.verlet_lambda, *w, k1, k2, k3[:H], k4[:H]))
        if kernel in (KERNEL_EXPEULER, KERNEL_ETD2):
            if kernel == KERNEL_EXPEULER:
                return int(advance_expeuler(*a, *self.expeuler_operator(float(dt)), *w, k1, k2))
            P1, P2, Q = self.exponential_matrices(float(dt))
            return int(advance_etd2(*a, P1, P2, Q, *w, k1, k2, k3))
        raise ValueError(f"method = {method!r} is not allowed: one of "
                         f"{', '.join(FIXED_STEP_METHODS)}")

    def advance_span(self, t0: float, t1: float, max_dt: float, y: np.ndarray,
                     u: np.ndarray | None = None) -> float:
        """RK4 from ``t0`` to ``t1`` [s], steps <= ``max_dt`` [s], split at :attr:`breakpoints`.

        ``y`` (shape (n_state,)) is advanced in place; returns the time [s] reached (``t1``
        unless the state stopped being finite).
        """
        k1, k2, k3, k4, yt = self._scratch
        return float(advance_rk4_span(
            self.model_id, float(t0), float(t1), float(max_dt), self.breakpoints, y, self.p,
            self.ip, self.fp, self.u if u is None else u, self.wR, self.wF, self.wM, k1, k2, k3,
            k4, yt))

    def exponential_matrices(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(P1, P2, Q)`` of the exponential integrators for step ``dt`` [s] (cached per dt).

        Built from the Jacobian at the initial (static equilibrium) state; only for the
        axial-torsional model, which is linear up to the small-twist ``sin`` and the bit torque.
        """
        if self.kind != "axial_torsional":
            raise ValueError("exponential integrators need the axial-torsional model (the full "
                             "3D model is far from linear under spin): use 'rk4' or 'verlet'")
        cache = self.__dict__.setdefault("_expm_cache", {})
        if dt not in cache:
            if len(cache) >= _EXPM_CACHE_SIZE:
                cache.pop(next(iter(cache)))
            cache[dt] = exponential_matrices(self.initial_jacobian, dt)
        return cache[dt]

    def expeuler_operator(self, dt: float) -> tuple[np.ndarray, ...]:
        """Exponential Euler's operator for step ``dt`` [s]: ``P1 = dt phi1(dt A)`` in the block
        form of ``block_split``, then the top drive's ramp vectors (3, n_state), or (0,
        n_state) when no drive moves (:func:`plant.integrators.add_drive_ramp`)."""
        cache = self.__dict__.setdefault("_p1_blocks", {})
        if dt not in cache:
            if len(cache) >= _EXPM_CACHE_SIZE:  # variable steps: keep the newest few
                cache.pop(next(iter(cache)))
            cache[dt] = (*block_split(self.exponential_matrices(dt)[0]), self._drive_ramp(dt))
        return cache[dt]

    def _drive_ramp(self, dt: float) -> np.ndarray:
        """The ramp vectors of :func:`plant.integrators.add_drive_ramp` for step ``dt`` [s].

        The drives that move: hoisting (the top spring and damper on body 1's axial motion)
        and a prescribed rotation (the torsional ones on its rotation). Each enters ``f`` as
        ``(K x(t) + C x'(t)) g``, ``g`` the unit vector of body 1's acceleration over its mass
        (polar inertia), ``x`` the drive's travel [m or rad]; in the equilibrium Jacobian
        ``A`` the torsional spring's ``sin`` is linear. Rows, summed over the drives times
        their speed: ``C P1 g``, ``K dt^2 phi2 g``, ``C dt^2 phi2 g + K dt^3 phi3 g``.
        """
        p = self.p
        n = self.n
        drives = []  # (speed, state index, 1 / inertia, K, C)
        if p[lay.HOIST] != 0.0:
            drives.append((p[lay.HOIST], 2 * n, p[lay.NP + lay.B_IM], p[lay.KT_AX],
                           p[lay.CT_AX]))
        if self.params.top_drive.mode == "prescribed" and p[lay.OMEGA0] != 0.0 \
                and p[lay.KT_TO] > 0.0:
            drives.append((p[lay.OMEGA0], 3 * n, p[lay.NP + lay.B_IJP], p[lay.KT_TO],
                           p[lay.CT_TO]))
        if not drives:
            return np.zeros((0, self.n_state))
        G = np.zeros((self.n_state, len(drives)))
        for j, (_speed, i, inv, _k, _c) in enumerate(drives):
            G[i, j] = inv
        W = polynomial_input_responses(self.initial_jacobian, G, dt)
        ramp = np.zeros((3, self.n_state))
        for j, (speed, _i, _inv, k, c) in enumerate(drives):
            ramp[0] += speed * c * W[0][:, j]
            ramp[1] += speed * k * W[1][:, j]
            ramp[2] += speed * (c * W[1][:, j] + k * W[2][:, j])
        return ramp

    @property
    def exponential_exclusions(self) -> list[str]:
        """Why the exact exponential step does not fit this model ([] when it does).

        It fits the axial-torsional chain, linear up to the small-twist ``sin``, with inputs
        it integrates exactly whatever the step: inputs held over a step (a top-drive speed
        command or motor torque), step loads (steps split at their switch times), and the top
        drive's prescribed hoisting and rotation (piecewise polynomial in time:
        :func:`plant.integrators.add_drive_ramp`). It does not fit the full 3D model (far
        from linear under spin) or the bit's nonlinear or oscillating inputs: the cutting bit
        (a unilateral contact and friction law), a bit torque (``tanh`` of the bit speed) and
        the prescribed bit displacement (a sine of the top-drive angle: exponential Euler
        would hold it over a step, a first-order error).
        """
        p = self.p
        out = []
        if self.kind != "axial_torsional":
            out.append(f"model = {self.kind!r} (not linear: the exact step needs "
                       "'axial_torsional')")
        if self.params.bit.model == "cutting":
            out.append("bit.model = 'cutting' (a nonlinear contact and friction law)")
        if p[lay.BIT_AMP] != 0.0 and p[lay.KB_AX] != 0.0:
            out.append("bit.displacement_amplitude > 0 (a sine of the top-drive angle, not "
                       "polynomial in time)")
        if p[lay.BIT_TORQUE] != 0.0:
            out.append("bit.torque > 0 (tanh of the bit speed: nonlinear)")
        return out

    @property
    def default_method(self) -> str:
        """The fastest accurate integrator for this model when the step size is not known:
        :meth:`method_for_step` with ``h = None``."""
        return self.method_for_step(None)

    def method_for_step(self, h: float | None) -> str:
        """The fastest accurate fixed-step method for communication steps of ``h`` [s].

        Exponential Euler, one exact step a communication step, when
        :attr:`exponential_exclusions` is empty: the linear axial-torsional chain, whose
        inputs held over a step, step loads (steps split at their switch times) and the top
        drive's prescribed hoisting and rotation ramps (``phi`` functions) it integrates
        exactly. Otherwise (:attr:`exponential_exclusions` says why), among the methods of
        :data:`plant.integrators.METHODS` marked ``automatic`` for this model kind (they met
        the accuracy bar of ``BENCHMARKS.md`` at their automatic step; explicit Runge-Kutta
        methods that evaluate the prescribed motions at their stage times, so a hoisting or
        rotation ramp is integrated to their order, its end a breakpoint), the fewest
        right-hand side evaluations per communication step, ``stages * ceil(h / stable
        step)`` (per unit time, ``stages / stable step``, for ``h = None``); ties go to fewer
        internal steps (less work besides the right-hand sides), then to the higher order.
        For the paper's 3D string at 0.25 ms (the closed loop) one step of Kutta's 3rd-order
        method beats one RK4 step; at 1 ms three RK4 steps tie with four 3-stage steps and
        RK4 is kept.
        """
        if not self.exponential_exclusions:
            return "expeuler"
        best: tuple[tuple[float, float, int], str] | None = None
        for spec in METHODS.values():
            if self.kind not in spec.automatic or not spec.radius:
                continue
            dt = stable_step(self.max_eigenvalue, spec.radius)
            if h is None:
                key = (spec.stages / dt, 1.0 / dt, -spec.order)
            else:
                n_sub = max(1, math.ceil(h / dt - 1e-9))
                key = (float(spec.stages * n_sub), float(n_sub), -spec.order)
            if best is None or key < best[0]:
                best = (key, spec.name)
        assert best is not None, "no automatic method in the table"
        return best[1]

    def advance_adaptive(self, t0: float, t1: float, y: np.ndarray, hstate: np.ndarray,
                         rtol: float = 1e-6, atol: float = 1e-9, u: np.ndarray | None = None,
                         max_steps: int = 1_000_000, stats: np.ndarray | None = None) -> int:
        """Adaptive Dormand-Prince 5(4) from ``t0`` to exactly ``t1`` [s], ``y`` in place.

        ``hstate`` (shape (1,)) carries the step proposal [s] between calls (<= 0: automatic).
        Returns 0 on success, a negative code on failure (see ``integrators.DP5_*``).
        """
        K = self.__dict__.get("_dp5_K")
        if K is None:
            K = self.__dict__.setdefault("_dp5_K", np.zeros((7, self.n_state)))
        st = np.zeros(3, dtype=np.int64) if stats is None else stats
        k1, k2 = self._scratch[:2]
        return int(
            advance_dopri5(self.model_id, float(t0), float(t1), y, hstate, st, float(rtol),
                           float(atol), int(max_steps), self.p, self.ip, self.fp,
                           self.u if u is None else u, self.wR, self.wF, self.wM, K, k1, k2)
        )
