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
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from femstudy.errors import require
from femstudy.fe import linsolve
from femstudy.fe.static import near_null_space, reduced, stiffness_factor

BETA, GAMMA = 0.25, 0.5


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
                    u0=None, v0=None, quasi_static: bool = False, energies: bool = False, method: str = "auto", console=None) -> TransientResult:
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
                 (two sparse products per step, a third of a step's cost on the femur)
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

    start = time.perf_counter()
    K, M = reduced(system, bc, "K"), reduced(system, bc, "M")
    Pf = P[bc.free]
    c0, c1 = 1 / (BETA * dt ** 2), GAMMA / (BETA * dt)
    K_eff = ((1 + c1 * beta_r) * K + (c0 + c1 * alpha) * M).tocsr()
    factor = linsolve.factorize(K_eff, method, near_null_space(system, bc), console)
    u = np.zeros(len(bc.free)) if u0 is None else np.asarray(u0, float)[bc.free]
    v = np.zeros(len(bc.free)) if v0 is None else np.asarray(v0, float)[bc.free]
    residual = Pf @ A[0] - K @ u - alpha * (M @ v) - beta_r * (K @ v)
    if np.any(residual):
        a = linsolve.factorize(M, method, near_null_space(system, bc)).solve(residual)
    else:
        a = np.zeros_like(u)
    setup = time.perf_counter() - start

    qs_shapes = None
    if quasi_static:
        qs_shapes = stiffness_factor(system, bc, method, console).solve(Pf)
        qs_shapes = bc.expand(qs_shapes.reshape(len(bc.free), -1))

    columns: dict[str, list] = {}

    def record(n, u, v):
        full = bc.expand(u)
        peak, node = max_nodal_norm(full)
        row = {"time_s": t[n], "max_deflection_mm": peak, "max_deflection_node": node}
        if energies:
            row.update(kinetic_energy_mJ=0.5 * v @ (M @ v), strain_energy_mJ=0.5 * u @ (K @ u))
        if qs_shapes is not None:
            row["quasi_static_max_deflection_mm"] = max_nodal_norm(qs_shapes @ A[n])[0]
        if observe is not None:
            row.update(observe(n, t[n], full))
        for key, value in row.items():
            columns.setdefault(key, []).append(value)
        if n in keep:
            fields[n] = full

    fields: dict[int, np.ndarray] = {}
    record(0, u, v)
    stepping = 0.0  # time in the Newmark update and solve, without recording and observe
    report_every = max(1, (len(t) - 1) // 10)
    for n in range(len(t) - 1):
        step_start = time.perf_counter()
        history = c0 * u + (1 / (BETA * dt)) * v + (1 / (2 * BETA) - 1) * a
        damping_history = c1 * u + (GAMMA / BETA - 1) * v + dt * (GAMMA / (2 * BETA) - 1) * a
        rhs = Pf @ A[n + 1] + M @ (history + alpha * damping_history)
        if beta_r:
            rhs += beta_r * (K @ damping_history)
        u_new = factor.solve(rhs, x0=u)
        a_new = c0 * (u_new - u) - (1 / (BETA * dt)) * v - (1 / (2 * BETA) - 1) * a
        v = v + dt * ((1 - GAMMA) * a + GAMMA * a_new)
        u, a = u_new, a_new
        stepping += time.perf_counter() - step_start
        record(n + 1, u, v)
        if console is not None and ((n + 1) % report_every == 0 or n + 2 == len(t)):
            console.progress(f"transient step {n + 1}/{len(t) - 1}, t = {t[n + 1]:.4g} s, "
                             f"max deflection {columns['max_deflection_mm'][-1]:.4g} mm")

    summary = {key: np.asarray(value) for key, value in columns.items()}
    result = TransientResult(t, summary, fields, factor.method,
                             {"setup_s": setup, "factor_s": factor.setup_s, "steps": len(t) - 1,
                              "per_step_s": stepping / (len(t) - 1), "total_s": time.perf_counter() - start})
    if qs_shapes is not None:
        peak_dyn = summary["max_deflection_mm"].max()
        peak_qs = summary["quasi_static_max_deflection_mm"].max()
        result.quasi_static = {"peak_transient_mm": peak_dyn, "peak_quasi_static_mm": peak_qs,
                               "dynamic_amplification": peak_dyn / peak_qs if peak_qs > 0 else np.nan}
    return result
