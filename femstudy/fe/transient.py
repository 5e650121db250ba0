"""Transient response M ü + C u̇ + K u = f(t) on the free DOFs: Newmark's average acceleration
rule (β = 1/4, γ = 1/2: unconditionally stable, second order, no numerical damping) with the
consistent mass and optional Rayleigh damping C = α M + β_R K. Units: u mm, v mm/s,
a mm/s², f N, t s, energies mJ (= N·mm).

The load is a few spatial patterns with time-varying amplitudes, f(t) = Σ_k a_k(t) f_k, and
the step is constant. The march is carried out in a reduced basis built with the study's one
factorisation of K_ff (:class:`~femstudy.fe.static.FactorizedSystem`), and *checked* against
the full equations:

1. Basis, on an exact factor: the static shapes K⁻¹P (and the initial state), then blocks
   K⁻¹M Q of the last block Q — load-dependent Ritz vectors (Wilson, Yuan & Dickens 1982), the
   Krylov space that both a quasi-static march (Δt ≫ natural periods: K̂ = K + 4M/Δt² ≈ K) and
   a resolved one live in to the accuracy the load's frequency content needs.
1'. On a factor whose solves are approximate (single precision, one substitution K̃⁻¹ each,
   ~1e-2 relative error on the femur) nothing is refined: every step's residual lies in the
   span of G = [P, MV, KV], kept orthonormal as Q_G (a QR grown by each block's [MQ, KQ]), and
   each new direction of Q_G is substituted once, X = K̃⁻¹Q_G — one call per block, its columns
   together. Then K̃⁻¹r_n = X (R_G z_n) for all steps at once, and the next block is this
   error's principal directions, those above :data:`DIRECTION_SHARE` of the target (at most
   max(:data:`MIN_DIRECTIONS`, 2k)): a block shrinks the static shapes' own error as a
   refinement step would and the inertia's as a Krylov block would. The static shapes need no
   solve of their own: they are the basis's Galerkin ones, V (VᵀKV)⁻¹VᵀP, whose residual lies
   in G's span too and is held to the same indicator. In a quasi-static march (steps of at
   least :data:`QUASI_STATIC_PERIODS` lowest periods) a block shrinks the indicator as a
   refinement step would, by the contraction seen so far or more: when that, times the last
   indicator, is within the target, the error's directions are added as the last block and
   not substituted again (its indicator is that estimate, as a refined static solve's last
   correction is not checked either). On the femur at 16 and 8 mm: 3 and 4 substitution calls
   of 2–8 columns, against 11 of two columns when each block was refined (docs/solver.md).
2. March: the Galerkin projection (VᵀKV, VᵀMV, VᵀP) is diagonalised; each of its modes is a
   damped oscillator and the average-acceleration rule for it is exactly the bilinear
   (Tustin) transform of the oscillator, a second-order recursive filter run by
   one vectorised recurrence over all modes. The step count costs almost nothing.
3. Check, at every step, against the *full* equations: the residual force
   r = M a + C v + K u − f, and the displacement it stands for, K⁻¹ r, relative to the
   largest displacement — the error indicator. Both norms come exactly, for all steps at
   once, from a QR factorisation of [MV, KV, P] and of [K⁻¹MV, V, K⁻¹P] (‖G z‖ = ‖R z‖); on
   an approximate factor the indicator is ‖K̃⁻¹r‖ (through X's Gram matrix), within the factor's
   contraction of the exact one.
   Blocks are added until the indicator is below :data:`INDICATOR_RTOL` or stops falling;
   the march is accepted below :data:`ACCEPT_RTOL`. Otherwise K̂ is factorised and the model
   steps (one substitution per step, outputs observed on the fly): the only case with a
   second factorisation.

The indicator, not the force residual, decides: in a resolved march the residual force is
dominated by the inertia of stiff, unresolved components (the average-acceleration rule
rings at the Nyquist frequency in them), which displaces the bone very little. Measured
against plain stepping (tests/test_fe_transient.py, docs/solver.md) the displacement error
stayed within 10× the indicator. Quasi-static runs (the thesis's 0.1 s steps on a femur
whose lowest mode is ~560 Hz) reach 1e-11 with 6 vectors.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from femstudy.errors import require
from femstudy.fe import linsolve
from femstudy.fe.static import FactorizedSystem
from femstudy.fe.subspace import GrowingGram, GrowingQR, grow_projection, orthonormal_complement, symmetric

log = logging.getLogger(__name__)

BETA, GAMMA = 0.25, 0.5
#: Error indicator the basis is enriched towards (plain stepping leaves ~1e-10 on the femur).
INDICATOR_RTOL = 1e-9
#: Largest error indicator ‖K⁻¹r‖ / max ‖u‖ at which the reduced march is accepted.
ACCEPT_RTOL = 1e-4
#: On an approximate factor, the error directions a block takes (:func:`preconditioned_march`):
#: those whose error is at least this fraction of the target, at most max(MIN_DIRECTIONS, 2k)
#: for k load patterns (each block's substitution has twice as many columns).
DIRECTION_SHARE = 0.1
MIN_DIRECTIONS = 4
#: Steps at least this many periods of the lowest mode long make a march quasi-static enough for
#: its blocks to shrink the error as refinement steps do (:func:`preconditioned_march`'s last
#: block): on the test tube the estimate held from 5 periods a step and failed at 1 and 2.
QUASI_STATIC_PERIODS = 10.0
#: Blocks of Ritz vectors tried (each one solve with k right-hand sides).
MAX_BLOCKS = 16
#: An out-of-balance force below this fraction of the forces it is the difference of is
#: round-off: a direct solve leaves 1e-10 to 1e-9 of the load (measured on the test tube),
#: and a force 1e-8 of the load moves the model far less than the accepted error indicator.
ROUNDOFF = 1e-8


@dataclass(frozen=True)
class StepCheck:
    """Does Δt resolve the lowest mode? Average acceleration lengthens a period T by
    ΔT/T ≈ (π²/12)(Δt/T)², under 1 % for Δt ≤ T/10; with Δt > T/2 the mode is aliased."""

    lowest_period_s: float
    dt_s: float
    steps_per_period: float
    period_elongation: float
    verdict: str  # "resolved", "under-resolved" or "quasi-static"


def step_check(lowest_period_s: float, dt_s: float) -> StepCheck:
    """How well a step Δt [s] resolves a period T [s] (:class:`StepCheck`)."""
    ratio = dt_s / lowest_period_s
    verdict = "resolved" if ratio <= 0.1 else "under-resolved" if ratio <= 0.5 else "quasi-static"
    elongation = np.pi ** 2 / 12 * ratio ** 2 if ratio <= 0.5 else np.nan
    return StepCheck(lowest_period_s, dt_s, 1.0 / ratio, float(elongation), verdict)


class Observer(Protocol):
    """What a transient hands its displacements to: the whole reduced history at once, or
    (stepping) one full field per step."""

    def reduced(self, basis: np.ndarray, coordinates: np.ndarray) -> None:
        """``basis`` (n_dofs, m) full-DOF vectors, ``coordinates`` (m, n_steps): u_n = basis @ coordinates[:, n]."""

    def step(self, n: int, u: np.ndarray) -> None:
        """The full displacement vector [mm] at step n."""


@dataclass(frozen=True, eq=False)
class TransientResult:
    """A march through ``time_s``.

    scheme       : "reduced" (u_n = basis @ coordinates[:, n]) or "stepping"
    basis        : (n_free, m) orthonormal Ritz vectors, or None
    coordinates  : (m, n_steps) reduced displacements, or None
    static_shapes: (n_free, k) K⁻¹ f_k: the quasi-static response is static_shapes @ a(t)
    residual     : max over steps of ‖M a + C v + K u − f‖ / max ‖f‖
    indicator    : max over steps of ‖K⁻¹(M a + C v + K u − f)‖ / max ‖u‖ (NaN when stepped:
                   stepping solves the full equations; an estimate when
                   ``timings["indicator_estimated"]``, module docstring 1')
    final_state  : full (u, v, a) at the last step, to continue from
    energies     : kinetic_energy_mJ, strain_energy_mJ per step (reduced march), else empty
    timings      : basis_s, march_s, check_s, total_s, vectors; factor_s for stepping
    """

    time_s: np.ndarray
    scheme: str
    solver: str
    basis: np.ndarray | None
    coordinates: np.ndarray | None
    static_shapes: np.ndarray
    residual: float
    indicator: float
    final_state: tuple
    free: np.ndarray = field(repr=False)
    n_dofs: int = 0
    energies: dict[str, np.ndarray] = field(default_factory=dict)
    timings: dict[str, float | list[float]] = field(default_factory=dict)

    @property
    def dt_s(self) -> float:
        return float(self.time_s[1] - self.time_s[0])

    @property
    def n_vectors(self) -> int:
        return 0 if self.basis is None else self.basis.shape[1]

    def full_basis(self) -> np.ndarray:
        """The basis as full-DOF vectors (zero on the clamps), (n_dofs, m)."""
        out = np.zeros((self.n_dofs, self.n_vectors))
        out[self.free] = self.basis
        return out

    def displacement(self, n: int) -> np.ndarray:
        """The full displacement vector [mm] at step n (reduced march only)."""
        require(self.scheme == "reduced", "a stepped transient keeps no history; observe it while it runs")
        u = np.zeros(self.n_dofs)
        u[self.free] = self.basis @ self.coordinates[:, n]
        return u


def solve_transient(fs: FactorizedSystem, patterns, amplitudes, times_s, *, damping=(0.0, 0.0), u0=None, v0=None,
                    observer: Observer | None = None, scheme: str = "auto",
                    rtol: float = INDICATOR_RTOL, accept_rtol: float = ACCEPT_RTOL,
                    static_shapes: np.ndarray | None = None) -> TransientResult:
    """March the clamped model through ``times_s`` (uniform steps) from (u0, v0) at times_s[0].

    Parameters
    ----------
    fs : FactorizedSystem
        The model with K_ff factorised; the reduced basis is built with that factorisation.
    patterns : ndarray, (n_dofs, k)
        Load patterns [N per unit amplitude], e.g. ``DrillPatch.patterns``.
    amplitudes : ndarray, (n_steps, k)
        Their amplitudes at each time, e.g. columns thrust_N, torque_Nmm.
    times_s : ndarray, (n_steps,)
        Uniform, increasing times [s].
    damping : (float, float)
        Rayleigh (α [1/s], β_R [s]): C = α M + β_R K.
    u0, v0 : ndarray, optional
        Initial displacement [mm] and velocity [mm/s] (full vectors; default at rest); the
        initial acceleration satisfies M a0 = f(t0) − K u0 − C v0.
    observer : Observer, optional
        Receives the reduced history at once, or each stepped field.
    scheme : {"auto", "stepping"}
        "auto" marches in the reduced basis when it passes the check, else steps.
    rtol, accept_rtol : float
        Error indicator to enrich the basis towards, and the largest one accepted.
    static_shapes : ndarray, (n_free, k), optional
        K_ff⁻¹ of the patterns' free rows, when an earlier march already solved for them.

    Returns
    -------
    TransientResult
    """
    t = np.asarray(times_s, dtype=float)
    P = np.asarray(patterns, dtype=float).reshape(fs.system.n_dofs, -1)
    A = np.asarray(amplitudes, dtype=float).reshape(len(t), -1)
    require(len(t) >= 2 and A.shape[1] == P.shape[1], "need at least two times and one amplitude per load pattern")
    dt = t[1] - t[0]
    require(dt > 0 and np.allclose(np.diff(t), dt, rtol=1e-9, atol=0),
            "the transient needs uniform, increasing time steps")
    require(damping[0] >= 0 and damping[1] >= 0, "Rayleigh damping coefficients must be non-negative")
    require(scheme in ("auto", "stepping"), f"unknown transient scheme '{scheme}': choose auto or stepping")
    start = time.perf_counter()
    free = fs.bc.free
    Pf = P[free]
    u = np.zeros(fs.n_free) if u0 is None else np.asarray(u0, float)[free]
    v = np.zeros(fs.n_free) if v0 is None else np.asarray(v0, float)[free]
    reduced = scheme == "auto" and fs.method != "amg"
    if static_shapes is not None:
        static_shapes = np.asarray(static_shapes, float)
    elif not (reduced and fs.factor.refines):  # an approximate factor's march finds them itself
        static_shapes = fs.factor.solve(Pf)
    common = dict(free=free, n_dofs=fs.system.n_dofs)
    if reduced:
        with linsolve.one_openblas_thread():
            march = (preconditioned_march if fs.factor.refines else reduced_march)(fs, Pf, A, dt, damping, (u, v),
                                                                                      static_shapes, rtol)
        if march is not None and march.indicator <= accept_rtol:
            static_shapes = march.static_shapes if static_shapes is None else static_shapes
            if observer is not None:
                basis = np.zeros((fs.system.n_dofs, march.basis.shape[1]))
                basis[free] = march.basis
                observer.reduced(basis, march.y)
            log.info("transient marched on %d Ritz vectors (error indicator %.1e, residual force %.1e of the load)",
                     march.basis.shape[1], march.indicator, march.residual)
            timings = {**march.timings, "vectors": march.basis.shape[1], "total_s": time.perf_counter() - start}
            return TransientResult(t, "reduced", fs.method, march.basis, march.y, static_shapes, march.residual,
                                   march.indicator, march.final_state(fs.bc), energies=march.energies(),
                                   timings=timings, **common)
        if march is not None:
            log.info("the reduced march leaves an error indicator of %.1e (above %.0e): stepping instead",
                     march.indicator, accept_rtol)
    if static_shapes is None:
        static_shapes = fs.factor.solve(Pf)
    stepped = _step(fs, Pf, A, t, damping, (u, v), observer)
    timings = {**stepped.pop("timings"), "total_s": time.perf_counter() - start}
    return TransientResult(t, "stepping", stepped["solver"], None, None, static_shapes, stepped["residual"],
                           float("nan"), stepped["final_state"], energies=stepped["energies"], timings=timings,
                           **common)


@dataclass(frozen=True, eq=False)
class _ReducedMarch:
    basis: np.ndarray          # V (n_free, m)
    y: np.ndarray              # reduced displacements (m, steps)
    vy: np.ndarray
    ay: np.ndarray
    Kr: np.ndarray
    Mr: np.ndarray
    residual: float            # max ‖M a + C v + K u − f‖ / max ‖f‖
    indicator: float           # max ‖K⁻¹(M a + C v + K u − f)‖ / max ‖u‖
    timings: dict[str, float | list[float]]
    static_shapes: np.ndarray | None = None  # K⁻¹P, when the march found them (preconditioned_march)

    def final_state(self, bc):
        return tuple(bc.expand(self.basis @ x[:, -1]) for x in (self.y, self.vy, self.ay))

    def energies(self) -> dict:
        return {"kinetic_energy_mJ": 0.5 * np.einsum("in,ij,jn->n", self.vy, self.Mr, self.vy),
                "strain_energy_mJ": 0.5 * np.einsum("in,ij,jn->n", self.y, self.Kr, self.y)}


def _load_scale(fs: FactorizedSystem, P, A, u) -> float:
    """The largest load ‖f_n‖ [N], or ‖K u0‖ when that is larger: the residual's scale."""
    scale = _column_norms(P, A.T).max()
    return max(scale, np.linalg.norm(fs.stiffness_times(u))) if np.any(u) else scale


def _initial_vectors(fs: FactorizedSystem, P, A, state, damping) -> list[np.ndarray]:
    """A start away from rest: its state and initial acceleration M⁻¹(f0 − K u0 − C v0) are in
    the full march's space from the first step on."""
    u, v = state
    initial = [x for x in (u, v) if np.any(x)]
    if initial:
        a0 = _initial_acceleration(fs, P @ A[0], u, v, damping)
        initial += [a0] if np.any(a0) else []
    return initial


class _Basis:
    """The growing orthonormal basis V, block by block, with VᵀKV and VᵀMV, and the march in it."""

    def __init__(self, n: int, capacity: int):
        self.V = np.empty((n, capacity), order="F")  # column-major: memory only for the columns written
        self.m, self.blocks = 0, []  # basis size; the column range of each block
        self.Kr = self.Mr = np.zeros((0, 0))

    def add(self, fs: FactorizedSystem, new: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Add what ``new`` adds to the span; returns its orthonormal block Q with KQ and MQ
        (None when it adds nothing)."""
        Q = orthonormal_complement(self.V[:, :self.m], new)
        if Q.shape[1] == 0:
            return None
        KQ, MQ = fs.stiffness_times(Q), fs.mass(Q)
        b = Q.shape[1]
        self.V[:, self.m:self.m + b] = Q
        self.blocks.append(slice(self.m, self.m + b))
        self.m += b
        self.Kr, self.Mr = grow_projection(self.Kr, self.basis, KQ, b), grow_projection(self.Mr, self.basis, MQ, b)
        return Q, KQ, MQ

    @property
    def basis(self) -> np.ndarray:
        return self.V[:, :self.m]

    def march(self, P, A, dt, damping, state):
        """Reduced (y, v, a) of every step and Z: the residual of step n is −[P, MQ0, KQ0, MQ1,
        KQ1, …] Z[:, n] (C = α M + β_R K folded into the acceleration and displacement rows)."""
        alpha, beta_r = damping
        V = self.basis
        y, vy, ay = _modal_newmark(symmetric(self.Kr), symmetric(self.Mr), V.T @ P, A, dt, damping,
                                   (V.T @ state[0], V.T @ state[1]))
        acceleration, displacement = ay + alpha * vy, y + beta_r * vy
        Z = np.vstack([-A.T] + [x[b] for b in self.blocks for x in (acceleration, displacement)])
        return y, vy, ay, Z

    def result(self, y, vy, ay, residual: float, indicator: float, static_shapes=None) -> _ReducedMarch:
        # V's first m columns stay as they are while later blocks are appended: a view, not a copy
        return _ReducedMarch(self.basis, y, vy, ay, symmetric(self.Kr), symmetric(self.Mr), residual, indicator,
                             {}, static_shapes)


class _Search:
    """A march's blocks: each one's indicator, the best march so far, the seconds spent (a
    stopwatch started with the search, read by :meth:`lap`)."""

    def __init__(self, rtol: float, **counts):
        self.rtol, self.best, self.history = rtol, None, []
        self.timings = {"basis_s": 0.0, "march_s": 0.0, "check_s": 0.0, **counts}
        self._last = time.perf_counter()

    def lap(self, key: str) -> None:
        """Add the seconds since the last lap (or the start) to ``timings[key]``."""
        now = time.perf_counter()
        self.timings[key] += now - self._last
        self._last = now

    def offer(self, indicator: float, result) -> bool:
        """Record a block's indicator, keeping ``result()`` if it is the best yet; True when
        the search is done (below the target, or stalled)."""
        self.history.append(indicator)
        if self.best is None or indicator < self.best.indicator:
            self.best = result()
        return indicator <= self.rtol or _stalled(self.history)

    def contraction(self) -> float:
        """The least a block has shrunk the indicator by: the first block's indicator (what one
        substitution leaves) or any block's over the one before, whichever is larger."""
        h = self.history
        return max([h[0]] + [after / before for before, after in zip(h, h[1:])])

    def finish(self) -> _ReducedMarch:
        self.best.timings.update(self.timings, indicator_by_block=self.history)
        return self.best


def reduced_march(fs: FactorizedSystem, P, A, dt, damping, state, static_shapes, rtol: float = INDICATOR_RTOL,
                  max_blocks: int = MAX_BLOCKS) -> _ReducedMarch | None:
    """The Newmark march in load-dependent Ritz vectors of an exact factor of K_ff (module
    docstring, 1), the best of the bases tried; None when there is no load and no initial state."""
    load_norm = _load_scale(fs, P, A, state[0])
    if load_norm == 0:
        return None
    new = np.column_stack([static_shapes] + _initial_vectors(fs, P, A, state, damping))
    capacity = new.shape[1] * max_blocks
    basis = _Basis(len(P), capacity)
    # the residual r = [P, MQ0, KQ0, MQ1, KQ1, …] z and K⁻¹r = [K⁻¹P, K⁻¹MQ0, Q0, …] z, QR-updated
    force, shift = GrowingQR(len(P), 2 * capacity + P.shape[1]), GrowingQR(len(P), 2 * capacity + P.shape[1])
    force.append(P)
    shift.append(static_shapes)
    search = _Search(rtol)
    for _ in range(max_blocks):
        added = basis.add(fs, new)
        if added is None:
            break
        Q, KQ, MQ = added
        new = fs.factor.solve(MQ)  # K⁻¹M Q: the next block, and the indicator's K⁻¹MV
        force.append(MQ, KQ)
        shift.append(new, Q)
        search.lap("basis_s")
        y, vy, ay, Z = basis.march(P, A, dt, damping, state)
        search.lap("march_s")
        residual = float(np.linalg.norm(force.R @ Z, axis=0).max() / load_norm)
        indicator = float(np.linalg.norm(shift.R @ Z, axis=0).max()
                          / max(np.linalg.norm(y, axis=0).max(), np.finfo(float).tiny))
        search.lap("check_s")
        if search.offer(indicator, lambda: basis.result(y, vy, ay, residual, indicator)):
            break
    return search.finish()


def preconditioned_march(fs: FactorizedSystem, P, A, dt, damping, state, static_shapes=None,
                         rtol: float = INDICATOR_RTOL, max_blocks: int = MAX_BLOCKS) -> _ReducedMarch | None:
    """The Newmark march on a factor whose solves are approximate (module docstring, 1'): one
    substitution call per block, nothing refined. Without ``static_shapes`` the start is K̃⁻¹P
    and the static shapes returned are the basis's Galerkin ones, V (VᵀKV)⁻¹VᵀP, held to the same
    indicator. None when there is no load and no initial state."""
    load_norm = _load_scale(fs, P, A, state[0])
    if load_norm == 0:
        return None
    k, tiny = P.shape[1], np.finfo(float).tiny
    initial = _initial_vectors(fs, P, A, state, damping)
    widest = max(MIN_DIRECTIONS, 2 * k)
    capacity = k + len(initial) + widest * max_blocks
    basis = _Basis(len(P), capacity)
    # the residuals' directions G = [P, MQ0, KQ0, …] = Q_G R_G (a QR: the residuals cancel in
    # it), and X = K̃⁻¹Q_G = Q_X R_X (through XᵀX: nothing cancels in X times R_G z)
    force, error = GrowingQR(len(P), 2 * capacity + k), GrowingGram(len(P), 2 * capacity + k)
    search = _Search(rtol, substitutions=1)
    timings = search.timings
    force.append(P)
    error.append(fs.factor.approximate(force.Q[:, :force.rows]))
    timings["columns"] = force.rows
    new = np.column_stack([error.X[:, :error.cols] if static_shapes is None else static_shapes] + initial)
    estimate = None  # the last block's indicator, when it is estimated rather than substituted
    for _ in range(max_blocks):
        added = basis.add(fs, new)
        if added is None:
            break
        _, KQ, MQ = added
        rows = force.rows
        force.append(MQ, KQ)
        if force.rows > rows and estimate is None:
            error.append(fs.factor.approximate(force.Q[:, rows:force.rows]))
            timings["substitutions"] += 1
            timings["columns"] += force.rows - rows
        search.lap("basis_s")
        y, vy, ay, Z = basis.march(P, A, dt, damping, state)
        search.lap("march_s")
        # with the static problem K s = P (no mass) beside the steps when the march finds its shapes
        columns, scale = [Z], [np.full(Z.shape[1], max(np.linalg.norm(y, axis=0).max(), tiny))]
        if static_shapes is None:
            shapes_r = np.linalg.solve(symmetric(basis.Kr), basis.basis.T @ P)
            rest = np.zeros_like(shapes_r)
            columns.append(np.vstack([-np.eye(k)] + [x[b] for b in basis.blocks for x in (rest, shapes_r)]))
            scale.append(np.maximum(np.linalg.norm(shapes_r, axis=0), tiny))
        C = force.R @ np.hstack(columns)  # the residuals in Q_G's coordinates
        residual = float(np.linalg.norm(C[:, :Z.shape[1]], axis=0).max() / load_norm)
        if estimate is None:
            D = (error.R @ C) / np.concatenate(scale)  # K̃⁻¹ of each, in Q_X's, relative to its answer
            indicator = float(np.linalg.norm(D, axis=0).max())
        else:
            indicator = estimate
        search.lap("check_s")
        def result():
            shapes = basis.basis @ shapes_r if static_shapes is None else static_shapes
            return basis.result(y, vy, ay, residual, indicator, shapes)

        done = search.offer(indicator, result)
        if estimate is not None:
            timings["indicator_estimated"] = True
            break
        if done:
            break
        # the next block: the error's principal directions that matter for the target
        U, sigma, _ = np.linalg.svd(D, full_matrices=False)
        taken = min(int(np.sum(sigma >= DIRECTION_SHARE * rtol)), widest)
        new = error.combine(U[:, :taken])
        # a block shrinks the error as a refinement step does; when the one the contraction seen
        # so far promises, and the directions left out, are within the target, it is the last
        # and is not substituted (as a refined static solve's last correction is not)
        left_out = float(sigma[taken]) if taken < sigma.size else 0.0
        promised = max(search.contraction() * indicator, left_out)
        if promised <= rtol and _quasi_static(basis, dt):
            estimate = promised
    return search.finish()


def _quasi_static(basis: _Basis, dt: float) -> bool:
    """Δt is at least :data:`QUASI_STATIC_PERIODS` periods of the basis's lowest mode. That Ritz
    frequency lies above the model's lowest one by the basis's error (a few per cent once the
    static shapes are in it), far inside the factor kept from where the estimate failed."""
    lowest = scipy.linalg.eigh(symmetric(basis.Kr), symmetric(basis.Mr), eigvals_only=True, subset_by_index=(0, 0))[0]
    return lowest > 0 and dt * np.sqrt(lowest) / (2 * np.pi) >= QUASI_STATIC_PERIODS


def _stalled(history: list[float], blocks: int = 4) -> bool:
    """The indicator has not halved over the last ``blocks`` blocks."""
    return len(history) > blocks and min(history[-blocks:]) > 0.5 * min(history[:-blocks])


def _modal_newmark(Kr, Mr, Pr, A, dt, damping, state):
    """Average-acceleration march of the reduced system (m DOFs) over all steps.

    In the modes Φ of (Kr, Mr) (ΦᵀMrΦ = I, ΦᵀKrΦ = diag ω²) each coordinate obeys
    q̈ + c q̇ + ω² q = g with c = α + β_R ω², and the trapezoidal rule for it is the bilinear
    transform s = (2/Δt)(1 − z⁻¹)/(1 + z⁻¹) of 1/(s² + c s + ω²):

        (4/Δt² + 2c/Δt + ω²) q_n + (2ω² − 8/Δt²) q_{n−1} + (4/Δt² − 2c/Δt + ω²) q_{n−2}
            = g_n + 2 g_{n−1} + g_{n−2},

    run from q_0 and one explicit step to q_1. Velocities follow from
    v_n + v_{n−1} = (2/Δt)(q_n − q_{n−1}), accelerations from the equation of motion.
    Returns reduced (y, v, a), each (m, n_steps), in the coordinates of Kr, Mr.
    """
    alpha, beta_r = damping
    omega2, Phi = scipy.linalg.eigh(Kr, Mr)
    omega2 = np.maximum(omega2, 0.0)
    c = alpha + beta_r * omega2
    g = (Phi.T @ Pr) @ A.T                              # (m, n_steps) modal loads
    q0 = np.linalg.solve(Phi, state[0])
    v0 = np.linalg.solve(Phi, state[1])
    a0 = g[:, 0] - c * v0 - omega2 * q0
    # one step of the recurrence: (4/Δt² + 2c/Δt + ω²) q1 = g1 + (4/Δt²) q0 + (4/Δt) v0 + a0 + c (2/Δt q0 + v0)
    q1 = (g[:, 1] + 4 / dt ** 2 * q0 + 4 / dt * v0 + a0 + c * (2 / dt * q0 + v0)) / (4 / dt ** 2 + 2 * c / dt + omega2)
    n_steps = g.shape[1]
    # the recurrence step by step for all modes at once (one row per step), its load side
    # summed first; scipy.signal.lfilter would run it mode by mode, but importing scipy.signal
    # costs 0.5–1 s, more than this loop takes for 30,000 steps (0.1 s)
    lead = 4 / dt ** 2 + 2 * c / dt + omega2
    a1, a2 = (2 * omega2 - 8 / dt ** 2) / lead, (4 / dt ** 2 - 2 * c / dt + omega2) / lead
    # (arrays of m × n_steps: the load side summed in place, so that memory stays at a few such
    # arrays whatever the step count)
    h = np.array(g[:, 2:].T)
    h += g[:, :-2].T
    h += g[:, 1:-1].T
    h += g[:, 1:-1].T
    h /= lead
    q = np.empty((n_steps, len(omega2)))
    q[0], q[1] = q0, q1
    for n in range(2, n_steps):
        q[n] = h[n - 2] - a1 * q[n - 1] - a2 * q[n - 2]
    del h
    vel = np.empty_like(q)
    vel[0] = v0
    for n in range(1, n_steps):  # v_n = −v_{n−1} + (2/Δt)(q_n − q_{n−1})
        vel[n] = (2 / dt) * (q[n] - q[n - 1]) - vel[n - 1]
    q, vel = q.T, vel.T
    acc = g - c[:, None] * vel - omega2[:, None] * q
    return Phi @ q, Phi @ vel, Phi @ acc


def _step(fs: FactorizedSystem, P, A, t, damping, state, observer) -> dict:
    """Plain stepping with K̂ = (1 + γβ_R/(βΔt)) K + (1/(βΔt²) + γα/(βΔt)) M factorised."""
    alpha, beta_r = damping
    dt = t[1] - t[0]
    c0, c1 = 1 / (BETA * dt ** 2), GAMMA / (BETA * dt)
    K, M = fs.K, fs.M
    start = time.perf_counter()
    K_eff = sp.csr_matrix(((1 + c1 * beta_r) * K.data + (c0 + c1 * alpha) * M.data, K.indices, K.indptr),
                          shape=K.shape)
    factor = linsolve.factorize(K_eff, fs.method, fs.near_null_space())
    u, v = state
    a = _initial_acceleration(fs, P @ A[0], u, v, damping)
    setup = time.perf_counter() - start
    load_norm = _column_norms(P, A.T).max()
    residual = 0.0
    kinetic, strain = [0.5 * v @ fs.mass(v)], [0.5 * u @ (K @ u)]
    if observer is not None:
        observer.step(0, fs.bc.expand(u))
    report_every = max(1, (len(t) - 1) // 10)
    for n in range(1, len(t)):
        f = P @ A[n]
        history = c0 * u + (1 / (BETA * dt)) * v + (1 / (2 * BETA) - 1) * a
        damping_history = c1 * u + (GAMMA / BETA - 1) * v + dt * (GAMMA / (2 * BETA) - 1) * a
        rhs = f + fs.mass(history + alpha * damping_history) + (beta_r * (K @ damping_history) if beta_r else 0)
        u_new = factor.solve(rhs, u)
        a_new = c0 * (u_new - u) - (1 / (BETA * dt)) * v - (1 / (2 * BETA) - 1) * a
        v = v + dt * ((1 - GAMMA) * a + GAMMA * a_new)
        u, a = u_new, a_new
        kinetic.append(0.5 * v @ fs.mass(v))
        strain.append(0.5 * u @ (K @ u))
        if load_norm > 0 and n % report_every == 0:  # spot checks: the stepped march is exact to round-off
            check = fs.mass(a + alpha * v) + K @ (u + beta_r * v) - f
            residual = max(residual, float(np.linalg.norm(check) / load_norm))
        if observer is not None:
            observer.step(n, fs.bc.expand(u))
        if n % report_every == 0 or n + 1 == len(t):
            log.info("transient step %d/%d, t = %.4g s", n, len(t) - 1, t[n],
                     extra={"progress": ("transient steps", n, len(t) - 1)})
    timings = {"factor_s": factor.setup_s, "setup_s": setup, "steps": len(t) - 1,
               "march_s": time.perf_counter() - start - setup}
    return {"solver": factor.method, "residual": residual, "timings": timings,
            "energies": {"kinetic_energy_mJ": np.array(kinetic), "strain_energy_mJ": np.array(strain)},
            "final_state": tuple(fs.bc.expand(x) for x in (u, v, a))}


def _initial_acceleration(fs: FactorizedSystem, f0: np.ndarray, u: np.ndarray, v: np.ndarray, damping) -> np.ndarray:
    """a0 = M⁻¹(f0 − K u0 − C v0) [mm/s²]; zero when that force is round-off (below
    :data:`ROUNDOFF` of ‖f0‖ and ‖K u0‖), as for a start from the quasi-static state u0 = K⁻¹f0
    without damping, where a solve would only turn round-off into a basis vector."""
    alpha, beta_r = damping
    Ku = fs.stiffness_times(u)
    r0 = f0 - Ku - alpha * fs.mass(v) - beta_r * (fs.stiffness_times(v))
    if np.linalg.norm(r0) <= ROUNDOFF * max(np.linalg.norm(f0), np.linalg.norm(Ku)):
        return np.zeros_like(u)
    return _solve_mass(fs, r0)


def _solve_mass(fs: FactorizedSystem, r: np.ndarray) -> np.ndarray:
    """M_ff⁻¹ r by Jacobi-preconditioned CG (the consistent mass is well conditioned)."""
    from scipy.sparse.linalg import LinearOperator, cg

    diagonal = fs.M.diagonal()
    x, info = cg(fs.M, r, rtol=1e-12, maxiter=1000, M=LinearOperator(fs.M.shape, matvec=lambda y: y / diagonal))
    require(info == 0, "the initial acceleration did not converge (M a0 = f0 − K u0 − C v0)")
    return x


def _column_norms(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """‖P x‖ for every column x of X, through the small Gram matrix PᵀP."""
    gram = P.T @ P
    return np.sqrt(np.maximum(np.einsum("in,ij,jn->n", X, gram, X), 0.0))
