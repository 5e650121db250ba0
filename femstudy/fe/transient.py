"""Transient response: M ü + C u̇ + K u = f(t) on the free DOFs, by Newmark's average
acceleration rule (β = 1/4, γ = 1/2: unconditionally stable, second-order, no numerical
damping) with consistent mass and optional Rayleigh damping C = α M + β_R K.

The load is a fixed set of spatial patterns with time-varying amplitudes,
f(t) = Σ_k a_k(t) f_k, and the step Δt is constant, so the effective stiffness
K̂ = K + 4/Δt² M + 2/Δt C is factorised once and every step is one forward/backward solve:

    K̂ u_{n+1} = f_{n+1} + M (4/Δt² u_n + 4/Δt v_n + a_n) + C (2/Δt u_n + v_n)
    a_{n+1} = 4/Δt² (u_{n+1} − u_n) − 4/Δt v_n − a_n,   v_{n+1} = v_n + Δt/2 (a_n + a_{n+1})

Units: u mm, v mm/s, a mm/s², f N, t s, energies mJ (= N·mm).

When Δt is much longer than the lowest natural period (the thesis's 0.1 s steps against a
femur whose first mode is hundreds of Hz), the rule cannot represent the vibration: each
step returns, to within the load change per step, the static solution for f_{n+1}. The
result is then quasi-static, and :func:`step_check` says so; docs/solver.md discusses it.
It also means the march lives in a few load-dependent Krylov vectors: :func:`krylov_march`
finds them with a handful of solves instead of one per step, checks that the projected march
satisfies the full equations of motion at every step, and otherwise leaves it to stepping.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from femstudy.errors import require
from femstudy.fe import linsolve
from femstudy.fe.static import mass_product, near_null_space, reduced, stiffness_factor

BETA, GAMMA = 0.25, 0.5
#: The Krylov march is accepted when its largest equilibrium residual is below this fraction
#: of the largest load (plain stepping leaves ~1e-10 on the femur: one solve's round-off).
RESIDUAL_RTOL = 1e-9
#: Blocks of Krylov vectors tried before plain stepping takes over (each costs one solve
#: with k right-hand sides, ~3 single solves; the femur at 0.1 s steps needs 3).
MAX_KRYLOV_BLOCKS = 5


@dataclass
class TransientResult:
    """Per-step summaries (arrays over steps, keyed by column name with units), the full
    displacement fields [mm] of the steps the caller asked to keep, and cost figures:
    timings setup_s (K̂, its factorisation, a0), factor_s, per_step_s (update and solve, not
    the recording or ``observe``), total_s."""

    time_s: np.ndarray
    summary: dict[str, np.ndarray]
    fields: dict[int, np.ndarray]
    solver: str
    timings: dict = field(default_factory=dict)
    quasi_static: dict | None = None
    scheme: str = "stepping"

    @property
    def dt_s(self) -> float:
        return float(self.time_s[1] - self.time_s[0])


def max_nodal_norm(u: np.ndarray) -> tuple[float, int]:
    """Largest nodal displacement magnitude [mm] of a full DOF vector, and its node."""
    norm = np.linalg.norm(u.reshape(-1, 3), axis=1)
    node = int(np.argmax(norm))
    return float(norm[node]), node


def step_check(lowest_period_s: float, dt_s: float) -> dict:
    """Does Δt resolve the lowest mode? Average acceleration lengthens a period T by
    ΔT/T ≈ (π²/12)(Δt/T)², under 1 % for Δt ≤ T/10; with Δt > T/2 the mode is aliased and
    the response is quasi-static."""
    ratio = dt_s / lowest_period_s
    verdict = ("resolved" if ratio <= 0.1 else "under-resolved" if ratio <= 0.5 else "quasi-static")
    return {"lowest_period_s": lowest_period_s, "dt_s": dt_s, "steps_per_period": 1.0 / ratio,
            "period_elongation": np.pi ** 2 / 12 * ratio ** 2 if ratio <= 0.5 else np.nan, "verdict": verdict}


def solve_transient(system, bc, patterns, amplitudes, times_s, *, damping=(0.0, 0.0), keep=(), observe=None,
                    u0=None, v0=None, quasi_static: bool = False, energies: bool = False, method: str = "auto",
                    scheme: str = "auto", console=None) -> TransientResult:
    """March the model through ``times_s`` (uniform steps) from the state (u0, v0) at times_s[0].

    patterns   : (n_dofs, k) load patterns [N per unit amplitude], e.g. DrillPatch.patterns
    amplitudes : (n_steps, k) their amplitudes at each time, e.g. columns thrust_N, torque_Nmm
    damping    : Rayleigh (α [1/s], β_R [s]); C = α M + β_R K
    keep       : step indices whose full displacement field is returned
    observe    : optional ``observe(step, t, u) -> dict`` adding summary columns per step
    u0, v0     : initial displacement [mm] and velocity [mm/s] (full vectors; default at rest);
                 the initial acceleration satisfies M a0 = f(t0) − K u0 − C v0
    quasi_static: also report the static response to f(t) at every step and the dynamic
                 amplification = max transient deflection / max quasi-static deflection (this
                 needs the factorisation of K as well as K̂; a static solve on the same
                 constraints shares it)
    energies   : also record kinetic_energy_mJ = ½ vᵀMv and strain_energy_mJ = ½ uᵀKu per step
                 (two sparse products per step)
    scheme     : "auto" marches on Krylov vectors when they reproduce the full march
                 (:func:`krylov_march`; a direct linear solver only), otherwise steps;
                 "stepping" always steps (one forward/backward substitution per step)
    """
    t = np.asarray(times_s, dtype=float)
    P = np.asarray(patterns, dtype=float).reshape(system.n_dofs, -1)
    A = np.asarray(amplitudes, dtype=float).reshape(len(t), -1)
    require(len(t) >= 2 and A.shape[1] == P.shape[1], "need at least two times and one amplitude per load pattern")
    dt = t[1] - t[0]
    require(dt > 0 and np.allclose(np.diff(t), dt, rtol=1e-9, atol=0),
            "the transient needs uniform, increasing time steps (the step matrix is factorised once)")
    alpha, beta_r = damping
    require(alpha >= 0 and beta_r >= 0, "Rayleigh damping coefficients must be non-negative")
    keep = set(range(len(t))[k] for k in keep)
    require(scheme in ("auto", "stepping"), f"unknown transient scheme '{scheme}': choose auto or stepping")

    start = time.perf_counter()
    K, M, mass = reduced(system, bc, "K"), reduced(system, bc, "M"), mass_product(system, bc)
    Pf = P[bc.free]
    c0, c1 = 1 / (BETA * dt ** 2), GAMMA / (BETA * dt)
    K_eff = sp.csr_matrix(((1 + c1 * beta_r) * K.data + (c0 + c1 * alpha) * M.data, K.indices, K.indptr),
                          shape=K.shape)  # K and M share their pattern (reduced)
    factor = linsolve.factorize(K_eff, method, near_null_space(system, bc), console)
    u = np.zeros(len(bc.free)) if u0 is None else np.asarray(u0, float)[bc.free]
    v = np.zeros(len(bc.free)) if v0 is None else np.asarray(v0, float)[bc.free]
    residual = Pf @ A[0]
    if u0 is not None or v0 is not None:
        residual = residual - K @ u - alpha * mass(v) - beta_r * (K @ v)
    if np.any(residual):
        a = linsolve.factorize(M, method, near_null_space(system, bc)).solve(residual)
    else:
        a = np.zeros_like(u)
    setup = time.perf_counter() - start

    march_start = time.perf_counter()
    reduction = None
    if scheme == "auto" and factor.method != "amg":
        reduction = krylov_march(factor, K.dot, mass, Pf, A, dt, damping, (u, v, a),
                                 max_blocks=min(MAX_KRYLOV_BLOCKS, (len(t) - 1) // 6))
    if reduction is not None:
        basis, states = reduction["basis"], reduction.pop("states")
        states = ((basis @ y, basis @ vy) for y, vy, _ in states)
    else:
        states = ((y, vy) for y, vy, _ in newmark(factor.solve, K.dot, mass, (Pf @ A[n] for n in range(1, len(t))),
                                                  dt, damping, (u, v, a)))
    qs_shapes = None
    if quasi_static:
        qs_shapes = stiffness_factor(system, bc, method, console).solve(Pf)
        qs_shapes = bc.expand(qs_shapes.reshape(len(bc.free), -1))

    columns: dict[str, list] = {}
    fields: dict[int, np.ndarray] = {}

    def record(n, u, v):
        full = bc.expand(u)
        peak, node = max_nodal_norm(full)
        row = {"time_s": t[n], "max_deflection_mm": peak, "max_deflection_node": node}
        if energies:
            row.update(kinetic_energy_mJ=0.5 * v @ mass(v), strain_energy_mJ=0.5 * u @ (K @ u))
        if qs_shapes is not None:
            row["quasi_static_max_deflection_mm"] = max_nodal_norm(qs_shapes @ A[n])[0]
        if observe is not None:
            row.update(observe(n, t[n], full))
        for key, value in row.items():
            columns.setdefault(key, []).append(value)
        if n in keep:
            fields[n] = full

    record(0, u, v)
    stepping = time.perf_counter() - march_start  # the march without recording and observe
    report_every = max(1, (len(t) - 1) // 10)
    for n in range(1, len(t)):
        step_start = time.perf_counter()
        u, v = next(states)
        stepping += time.perf_counter() - step_start
        record(n, u, v)
        if console is not None and (n % report_every == 0 or n + 1 == len(t)):
            console.progress(f"transient step {n}/{len(t) - 1}, t = {t[n]:.4g} s, "
                             f"max deflection {columns['max_deflection_mm'][-1]:.4g} mm")

    summary = {key: np.asarray(value) for key, value in columns.items()}
    timings = {"setup_s": setup, "factor_s": factor.setup_s, "steps": len(t) - 1,
               "per_step_s": stepping / (len(t) - 1), "total_s": time.perf_counter() - start}
    if reduction is not None:
        timings["krylov_vectors"] = reduction["basis"].shape[1]
        timings["krylov_residual"] = reduction["residual"]
        if console is not None:
            console.progress(f"transient marched on {timings['krylov_vectors']} Krylov vectors "
                             f"(largest equilibrium residual {reduction['residual']:.1e} of the load)")
    result = TransientResult(t, summary, fields, factor.method, timings,
                             scheme="krylov" if reduction is not None else "stepping")
    if qs_shapes is not None:
        peak_dyn = summary["max_deflection_mm"].max()
        peak_qs = summary["quasi_static_max_deflection_mm"].max()
        result.quasi_static = {"peak_transient_mm": peak_dyn, "peak_quasi_static_mm": peak_qs,
                               "dynamic_amplification": peak_dyn / peak_qs if peak_qs > 0 else np.nan}
    return result


def newmark(solve, stiffness, mass, loads, dt, damping, state):
    """Yield (u, v, a) after each step of the average-acceleration recurrence (module
    docstring) from ``state`` = (u, v, a), one step per load vector f_{n+1} in ``loads``.
    ``solve(r, x0)`` applies K̂⁻¹, ``stiffness`` K and ``mass`` M: sparse on the free DOFs, or
    the dense projections of :func:`krylov_march`."""
    alpha, beta_r = damping
    c0, c1 = 1 / (BETA * dt ** 2), GAMMA / (BETA * dt)
    u, v, a = state
    for f in loads:
        history = c0 * u + (1 / (BETA * dt)) * v + (1 / (2 * BETA) - 1) * a
        damping_history = c1 * u + (GAMMA / BETA - 1) * v + dt * (GAMMA / (2 * BETA) - 1) * a
        rhs = f + mass(history + alpha * damping_history)
        if beta_r:
            rhs = rhs + beta_r * stiffness(damping_history)
        u_new = solve(rhs, u)
        a_new = c0 * (u_new - u) - (1 / (BETA * dt)) * v - (1 / (2 * BETA) - 1) * a
        v = v + dt * ((1 - GAMMA) * a + GAMMA * a_new)
        u, a = u_new, a_new
        yield u, v, a


def krylov_march(factor, stiffness, mass, P, A, dt, damping, state, rtol: float = RESIDUAL_RTOL,
                 max_blocks: int = MAX_KRYLOV_BLOCKS):
    """The Newmark march projected on load-dependent Krylov vectors, or None when that does
    not reproduce the full march.

    Every step of the full recurrence solves K̂ u = f + M h (+ K terms): from a start in
    span{u0, v0, a0} its states stay in the block Krylov space spanned by K̂⁻¹P, (K̂⁻¹M) K̂⁻¹P,
    (K̂⁻¹M)² K̂⁻¹P, … and u0, v0, a0 (K̂⁻¹K is a combination of I and K̂⁻¹M). When Δt is long
    against the natural periods, ‖K̂⁻¹M‖ ≈ 4/(Δt² ω₁²) is tiny and a few blocks hold the
    whole march to round-off: the femur at 0.1 s steps needs three, where plain stepping
    needs one substitution per step. Blocks are added until the reduced march (Galerkin
    projection, the same recurrence on VᵀK̂V, VᵀMV, VᵀP) satisfies the *full* equilibrium at
    every step, ‖M a + C v + K u − f‖ ≤ rtol · max‖f‖ — the equation the full march solves
    with one factorisation's round-off, ~1e-10 on the femur. Gives up (None) after
    ``max_blocks`` blocks, or earlier when the residual's decline per block predicts that
    the cap will not suffice: the caller then steps.

    P : (n, k) load patterns, A (n_steps, k) amplitudes; state (u, v, a) at A[0]'s time.
    Returns {"basis": V (n, m), "states": [(y, v_y, a_y) per step], "residual": float}.
    """
    alpha, beta_r = damping
    n_steps = len(A) - 1
    load_scale = np.linalg.norm(P @ A[1:].T, axis=0).max()
    if np.any(state[0]):
        load_scale = max(load_scale, np.linalg.norm(stiffness(state[0])))
    if load_scale == 0:
        return None
    V = np.zeros((len(P), 0))
    KV, MV = V, V
    new = np.column_stack([factor.solve(P)] + [x for x in state if np.any(x)])
    residuals = []
    for block in range(max_blocks):
        Q = _orthonormal_complement(V, new)
        if Q.shape[1] == 0:
            break
        V, KV, MV = np.hstack([V, Q]), np.hstack([KV, stiffness(Q)]), np.hstack([MV, mass(Q)])
        Kr, Mr = V.T @ KV, V.T @ MV
        Kr, Mr = (Kr + Kr.T) / 2, (Mr + Mr.T) / 2
        cho = scipy.linalg.cho_factor(Kr * (1 + GAMMA / (BETA * dt) * beta_r)
                                      + Mr * (1 / (BETA * dt ** 2) + GAMMA / (BETA * dt) * alpha))
        Pr = V.T @ P
        states = list(newmark(lambda r, _: scipy.linalg.cho_solve(cho, r), lambda y: Kr @ y, lambda y: Mr @ y,
                              (Pr @ A[n] for n in range(1, n_steps + 1)), dt, damping,
                              tuple(V.T @ x for x in state)))
        y, vy, ay = (np.array(s).T for s in zip(*states))  # (m, steps) each
        # M a + C v + K u − f at every step, as one product
        equilibrium = np.hstack([MV, KV, P]) @ np.vstack([ay + alpha * vy, y + beta_r * vy, -A[1:].T])
        residuals.append(np.linalg.norm(equilibrium, axis=0).max() / load_scale)
        if residuals[-1] <= rtol:
            return {"basis": V, "states": states, "residual": residuals[-1]}
        if len(residuals) >= 2:  # geometric decline: will the remaining blocks get there?
            rate = min(residuals[-1] / residuals[-2], 1.0)
            if residuals[-1] * rate ** (max_blocks - 1 - block) > rtol:
                return None
        new = factor.solve(mass(Q))
    return None


def _orthonormal_complement(V: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Orthonormal columns spanning what W adds to span(V) (V orthonormal); directions under
    1e-12 of W's own size are round-off and dropped."""
    scale = np.linalg.norm(W, axis=0).max()
    for _ in range(2):  # classical Gram–Schmidt twice is orthogonal to working precision
        W = W - V @ (V.T @ W)
    U, sigma, _ = np.linalg.svd(W, full_matrices=False)
    return U[:, sigma > 1e-12 * scale]
