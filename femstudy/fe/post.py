"""Stresses, von Mises, nodal fields for display and the per-step response summary.

Stress σ = D B u_e [MPa] is evaluated at the stiffness quadrature points (4 per P2 tet,
where the P2 stress is most accurate; 1 per P1 tet). von Mises:
σ_vm = √(½[(σxx−σyy)² + (σyy−σzz)² + (σzz−σxx)²] + 3(τyz² + τxz² + τxy²)).

Stresses next to the load patch's edge do not converge under mesh refinement (the
traction jumps there), so :func:`response` reports the maximum both overall and outside an
exclusion radius around the footprint centre.
"""

from __future__ import annotations

import numpy as np

from femstudy.fe.assembly import CHUNK, jacobians, strain_matrices
from femstudy.femur_model import REGION_NAMES


def _chunks(n: int):
    for start in range(0, n, CHUNK):
        yield np.arange(start, min(start + CHUNK, n))


def element_stress(system, u: np.ndarray, cells: np.ndarray | None = None) -> np.ndarray:
    """σ (n, nq, 6) [MPa], Voigt [xx, yy, zz, yz, xz, xy], at the quadrature points of ``cells``."""
    cells = np.arange(system.n_tets) if cells is None else np.asarray(cells)
    out = np.empty((len(cells), len(system.ref.weights), 6))
    dofs = 3 * system.cells[:, :, None] + np.arange(3)
    for part in _chunks(len(cells)):
        idx = cells[part]
        B, _ = strain_matrices(system, idx)
        strain = B @ u[dofs[idx].reshape(len(idx), 1, -1, 1)]
        out[part] = (system.materials.D[system.materials.index[idx]][:, None] @ strain)[..., 0]
    return out


def von_mises(stress: np.ndarray) -> np.ndarray:
    """σ_vm [MPa] of Voigt stresses (..., 6)."""
    sxx, syy, szz, syz, sxz, sxy = np.moveaxis(stress, -1, 0)
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2)
                   + 3.0 * (syz ** 2 + sxz ** 2 + sxy ** 2))


def _barycentric_at_quadrature(system) -> np.ndarray:
    X = system.ref.points
    return np.vstack([1 - X.sum(axis=0), X]).T  # (nq, 4): P1 shape functions at the points


def quadrature_points(system, cells: np.ndarray | None = None) -> np.ndarray:
    """Coordinates (n, nq, 3) [mm] of the stress points."""
    cells = np.arange(system.n_tets) if cells is None else np.asarray(cells)
    return np.einsum("qk,ekj->eqj", _barycentric_at_quadrature(system), system.mesh.p.T[system.mesh.t.T[cells]])


def von_mises_nodal(system, u: np.ndarray) -> np.ndarray:
    """σ_vm [MPa] at the mesh vertices for display: the lumped L2 projection onto linear
    fields, σ_i = Σ_e Σ_q dV_q N_i(x_q) σ_vm,q / Σ_e Σ_q dV_q N_i(x_q). It averages across
    material interfaces; use the quadrature-point values for maxima."""
    vm = von_mises(element_stress(system, u))
    N = _barycentric_at_quadrature(system)
    _, det = jacobians(system.mesh.p.T, system.mesh.t.T)
    dV = np.abs(det)[:, None] * system.ref.weights
    t = system.mesh.t.T
    numerator = np.bincount(t.ravel(), np.einsum("eq,qk,eq->ek", dV, N, vm).ravel(), minlength=system.mesh.nvertices)
    denominator = np.bincount(t.ravel(), np.einsum("eq,qk->ek", dV, N).ravel(), minlength=system.mesh.nvertices)
    return numerator / denominator


def displacement_magnitude(system, u: np.ndarray) -> np.ndarray:
    """|u| [mm] at every node (vertices, then P2 edge mid-nodes)."""
    return np.linalg.norm(u.reshape(-1, 3), axis=1)


def response(system, u: np.ndarray, patch, exclusion_radius_mm: float) -> dict:
    """Summary of one displacement field u [mm] under the drill ``patch``:

    max_deflection_mm and its node's coordinates; drill_point_deflection_mm (magnitude of
    the footprint-averaged displacement) and drill_point_axial_mm (its component along the
    drill); max_von_mises_MPa overall and outside ``exclusion_radius_mm`` of the footprint
    centre, with locations; per-region maxima; strain_energy_mJ = ½ uᵀ K u.
    """
    magnitude = displacement_magnitude(system, u)
    node = int(np.argmax(magnitude))
    drill = patch.mean @ u
    vm = von_mises(element_stress(system, u))
    xq = quadrature_points(system)
    outside = np.linalg.norm(xq - patch.centre, axis=2) > exclusion_radius_mm
    flat = int(np.argmax(vm))
    out = {"max_deflection_mm": float(magnitude[node]), "max_deflection_at_mm": system.nodes[node].tolist(),
           "drill_point_deflection_mm": float(np.linalg.norm(drill)),
           "drill_point_axial_mm": float(drill @ patch.axis),
           "max_von_mises_MPa": float(vm.flat[flat]), "max_von_mises_at_mm": xq.reshape(-1, 3)[flat].tolist(),
           "strain_energy_mJ": float(0.5 * u @ (system.K @ u))}
    if outside.any():
        masked = np.where(outside, vm, -np.inf)
        flat_out = int(np.argmax(masked))
        out["max_von_mises_outside_MPa"] = float(masked.flat[flat_out])
        out["max_von_mises_outside_at_mm"] = xq.reshape(-1, 3)[flat_out].tolist()
    else:
        out["max_von_mises_outside_MPa"], out["max_von_mises_outside_at_mm"] = np.nan, None
    regions = {}
    for code in np.unique(system.region):
        cells = system.region == code
        nodes = np.unique(system.cells[cells])
        regions[REGION_NAMES.get(int(code), str(code))] = {
            "max_von_mises_MPa": float(vm[cells].max()), "max_deflection_mm": float(magnitude[nodes].max())}
    out["regions"] = regions
    return out
