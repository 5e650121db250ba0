"""Stresses, von Mises stress and nodal fields for display.

Stress σ = D ε(u) [MPa] is evaluated at the stiffness quadrature points (4 per P2 tet,
where the P2 stress is most accurate; 1 per P1 tet). Voigt order [xx, yy, zz, yz, xz, xy].
von Mises: σ_vm = √(½[(σxx−σyy)² + (σyy−σzz)² + (σzz−σxx)²] + 3(τyz² + τxz² + τxy²)) = ‖T σ‖₂
with the 5×6 matrix :data:`VON_MISES_ROWS` (an orthonormal basis of the deviator, weighted),
which makes σ_vm the 2-norm of a linear function of u: the bounds of
:mod:`femstudy.fe.outputs` rest on that.

Stresses are linear in u, so the stresses of many displacement fields (a transient's basis)
are computed in one pass over the elements by :func:`stress_projection`.
"""

from __future__ import annotations

import numpy as np

from femstudy.fe.assembly import CHUNK, jacobians

#: T with σ_vm = ‖T σ‖₂: √(3/2)(σxx − σyy)/√2, √(3/2)(σxx + σyy − 2σzz)/√6, √3 τyz, √3 τxz, √3 τxy.
VON_MISES_ROWS = np.array([
    [np.sqrt(3 / 4), -np.sqrt(3 / 4), 0, 0, 0, 0],
    [0.5, 0.5, -1.0, 0, 0, 0],
    [0, 0, 0, np.sqrt(3), 0, 0],
    [0, 0, 0, 0, np.sqrt(3), 0],
    [0, 0, 0, 0, 0, np.sqrt(3)],
])


def _chunks(n: int):
    for start in range(0, n, CHUNK):
        yield np.arange(start, min(start + CHUNK, n))


def _element_dofs(system, cells: np.ndarray) -> np.ndarray:
    """(n, 3 nbf) DOF numbers of ``cells``, node-major (a node's x, y, z together)."""
    return (3 * system.cells[cells][:, :, None] + np.arange(3)).reshape(len(cells), -1)


#: (i, j) of the Voigt strains [xx, yy, zz, yz, xz, xy]; the shears are engineering (2 ε_ij).
VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))


def stress_projection(system, X: np.ndarray, cells: np.ndarray | None = None) -> np.ndarray:
    """σ (n, nq, 6, k) [MPa] at the quadrature points of ``cells`` (default all) for each of the
    k displacement fields in the columns of X (n_dofs, k) [mm].

    From the displacement gradients ∂u_i/∂x_j = Σ_a ∂N_a/∂x_j u_ai (one small product per
    point for all k fields), then ε in Voigt form and σ = D ε: no strain-displacement matrix B
    with its zeros is formed (a third of the time on the default femur, equal to 1e-16)."""
    X = np.asarray(X, float).reshape(system.n_dofs, -1)
    k = X.shape[1]
    cells = np.arange(system.n_tets) if cells is None else np.asarray(cells)
    nq = len(system.ref.weights)
    out = np.empty((len(cells), nq, 6, k))
    mats = system.materials
    for part in _chunks(len(cells)):
        idx = cells[part]
        invJ, _ = jacobians(system.mesh.p.T, system.mesh.t.T[idx])
        G = np.einsum("qam,emj->eqja", system.ref.grad, invJ)               # ∂N_a/∂x_j: (n, nq, 3, nbf)
        U = X[_element_dofs(system, idx)].reshape(len(idx), 1, -1, 3 * k)  # u_ai per field: (n, 1, nbf, 3k)
        gradient = (G @ U).reshape(len(idx), nq, 3, 3, k)                  # [.., j, i, k] = ∂u_i/∂x_j
        strain = np.empty((len(idx), nq, 6, k))
        for row, (i, j) in enumerate(VOIGT):
            strain[:, :, row] = gradient[:, :, j, i] + (gradient[:, :, i, j] if i != j else 0.0)
        out[part] = mats.D[mats.index[idx]][:, None] @ strain
    return out


def element_stress(system, u: np.ndarray, cells: np.ndarray | None = None) -> np.ndarray:
    """σ (n, nq, 6) [MPa] at the quadrature points of ``cells`` for one displacement u [mm]."""
    return stress_projection(system, u, cells)[..., 0]


def von_mises(stress: np.ndarray) -> np.ndarray:
    """σ_vm [MPa] of Voigt stresses (..., 6)."""
    return np.linalg.norm(stress @ VON_MISES_ROWS.T, axis=-1)


def _barycentric_at_quadrature(system) -> np.ndarray:
    X = system.ref.points
    return np.vstack([1 - X.sum(axis=0), X]).T  # (nq, 4): P1 shape functions at the points


def quadrature_points(system, cells: np.ndarray | None = None) -> np.ndarray:
    """Coordinates (n, nq, 3) [mm] of the stress points."""
    cells = np.arange(system.n_tets) if cells is None else np.asarray(cells)
    return np.einsum("qk,ekj->eqj", _barycentric_at_quadrature(system), system.mesh.p.T[system.mesh.t.T[cells]])


def nodal_average(system, values_at_points: np.ndarray) -> np.ndarray:
    """A quadrature-point field (n_tets, nq), or several (n_tets, nq, k), projected onto the mesh
    vertices for display: the lumped L2 projection σ_i = Σ_e Σ_q dV_q N_i(x_q) σ_q /
    Σ_e Σ_q dV_q N_i(x_q); (n_vertices,) or (n_vertices, k). It averages across material
    interfaces; use the quadrature-point values for maxima."""
    N = _barycentric_at_quadrature(system)
    _, det = jacobians(system.mesh.p.T, system.mesh.t.T)
    dV = np.abs(det)[:, None] * system.ref.weights
    t = system.mesh.t.T.ravel()
    values = np.asarray(values_at_points, float)
    columns = values.reshape(values.shape[:2] + (-1,))
    denominator = np.bincount(t, np.einsum("eq,qk->ek", dV, N).ravel(), minlength=system.mesh.nvertices)
    out = np.column_stack([np.bincount(t, np.einsum("eq,qk,eq->ek", dV, N, columns[:, :, j]).ravel(),
                                       minlength=system.mesh.nvertices) for j in range(columns.shape[2])])
    out /= denominator[:, None]
    return out.reshape((-1,) + values.shape[2:])


def von_mises_nodal(system, u: np.ndarray) -> np.ndarray:
    """σ_vm [MPa] of one displacement u at the mesh vertices (:func:`nodal_average`)."""
    return nodal_average(system, von_mises(element_stress(system, u)))


def displacement_magnitude(system, u: np.ndarray) -> np.ndarray:
    """|u| [mm] at every node (vertices, then P2 edge mid-nodes)."""
    return np.linalg.norm(u.reshape(-1, 3), axis=1)
