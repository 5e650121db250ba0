"""The global outputs of many loadings from two unit responses, exactly.

The model is linear: under a patch thrust F and torque T the displacement is u = F s₁ + T s₂,
s₁, s₂ the responses to a unit thrust [1 N] and torque [1 N·mm] (the study's static shapes
K⁻¹P; loads change over seconds against a lowest mode of hundreds of Hz, so the response is
quasi-static to (f_load/f₁)², as the study's dynamic amplification shows). So

* the drill point's displacement is D (F, T)ᵀ with D = (footprint mean) · [s₁ s₂], (3 × 2);
* a node's |u|² = F² aₙ + 2FT bₙ + T² cₙ (aₙ = |s₁ₙ|², bₙ = s₁ₙ·s₂ₙ, cₙ = |s₂ₙ|²).

The maximum deflection over the nodes depends on (F, T) through its direction θ only (times
|(F, T)|²): with Qₙ(θ) = |u_n|² at unit load in direction θ, |dQₙ/dθ| ≤ 2rₙ, so on a grid of
spacing Δ covering the directions the samples take, a node can be the largest anywhere only if
at the nearest grid angle it is within 2RΔ of the largest (R = max rₙ). Those *candidate* nodes
(tens of the femur's tens of thousands) give the exact maximum of every sample and time step
(:class:`Envelope`; test against the maximum over all nodes). Units: mm, N, N·mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Grid angles per radian of the directions spanned by the samples' loads.
GRID_PER_RADIAN = 2000
#: Nodes × angles evaluated at once (memory of one block: 8 bytes each).
BLOCK = 4_000_000


@dataclass(frozen=True)
class UnitResponses:
    """What the global outputs need of the responses to a unit thrust and torque.

    fields : (n_dofs, 2) displacements [mm per N, mm per N·mm], DOFs node by node
    drill_point : (3, 2) the drill footprint's mean displacement per unit load
    """

    fields: np.ndarray
    drill_point: np.ndarray

    @classmethod
    def of(cls, fields: np.ndarray, patch) -> "UnitResponses":
        """From the full unit fields and the model's :class:`femstudy.fe.DrillPatch`."""
        fields = np.asarray(fields, float)
        return cls(fields, np.asarray(patch.mean @ fields))

    def node_forms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(aₙ, bₙ, cₙ) of |uₙ|² = F² a + 2FT b + T² c for every node."""
        s = self.fields.reshape(-1, 3, 2)
        return (np.einsum("ni,ni->n", s[:, :, 0], s[:, :, 0]), np.einsum("ni,ni->n", s[:, :, 0], s[:, :, 1]),
                np.einsum("ni,ni->n", s[:, :, 1], s[:, :, 1]))

    def drill_point_mm(self, loads: np.ndarray) -> np.ndarray:
        """|D (F, T)| [mm] for loads (..., 2)."""
        return np.linalg.norm(loads @ self.drill_point.T, axis=-1)

    def max_deflection_mm(self, loads: np.ndarray) -> np.ndarray:
        """max over nodes of |u| [mm] for loads (..., 2), over every node (the reference)."""
        a, b, c = self.node_forms()
        F, T = loads[..., 0, None], loads[..., 1, None]
        return np.sqrt(np.maximum(F * F * a + 2 * F * T * b + T * T * c, 0.0).max(axis=-1))


@dataclass(frozen=True)
class Envelope:
    """The candidate nodes for the largest |u| over the directions of a set of loads.

    nodes : candidate node indices; a, b, c : their forms (see the module docstring)
    """

    nodes: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray

    @classmethod
    def of(cls, units: UnitResponses, loads: np.ndarray) -> "Envelope":
        """The candidates for every load direction in ``loads`` (..., 2)."""
        a, b, c = units.node_forms()
        F, T = loads[..., 0].ravel(), loads[..., 1].ravel()
        scale = np.sqrt(c.max() / max(a.max(), 1e-300))  # T' = scale T: a unit F and T' move the model alike
        theta = np.arctan2(T * scale, F)[np.hypot(F, T) > 0]
        if theta.size == 0:
            return cls(np.zeros(0, int), np.zeros(0), np.zeros(0), np.zeros(0))
        # Q(θ) = m + p cos 2θ + q sin 2θ in the scaled variables; the largest slope 2r
        a2, b2, c2 = a, b / scale, c / scale ** 2
        m, p, q = (a2 + c2) / 2, (a2 - c2) / 2, b2
        R = float(np.hypot(p, q).max())
        lo, hi = float(theta.min()), float(theta.max())
        n_grid = max(2, int(np.ceil((hi - lo) * GRID_PER_RADIAN)) + 1)
        grid = np.linspace(lo, hi, n_grid)
        delta = (hi - lo) / (n_grid - 1)
        keep = np.zeros(len(a), bool)
        step = max(1, BLOCK // len(a))
        for start in range(0, n_grid, step):
            g = grid[start:start + step]
            Q = m[:, None] + p[:, None] * np.cos(2 * g) + q[:, None] * np.sin(2 * g)
            keep |= (Q >= Q.max(axis=0) - 2 * R * delta - 1e-15 * Q.max()).any(axis=1)
        nodes = np.flatnonzero(keep)
        return cls(nodes, a[nodes], b[nodes], c[nodes])

    def max_deflection_mm(self, loads: np.ndarray) -> np.ndarray:
        """max over nodes of |u| [mm] for loads (..., 2) whose directions the envelope covers."""
        F, T = loads[..., 0, None], loads[..., 1, None]
        q = F * F * self.a + 2 * F * T * self.b + T * T * self.c
        return np.sqrt(np.maximum(q, 0.0).max(axis=-1, initial=0.0))
