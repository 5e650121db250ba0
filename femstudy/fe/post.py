"""Stresses, von Mises, nodal fields for display and the per-step response summary.

Stress σ = D B u_e [MPa] is evaluated at the stiffness quadrature points (4 per P2 tet,
where the P2 stress is most accurate; 1 per P1 tet). von Mises:
σ_vm = √(½[(σxx−σyy)² + (σyy−σzz)² + (σzz−σxx)²] + 3(τyz² + τxz² + τxy²)).

Stresses next to the load patch's edge do not converge under mesh refinement (the
traction jumps there), so :func:`response` reports the maximum both overall and outside an
exclusion radius around the footprint centre.

Stresses are linear in u: σ = S u with S = D B stacked over every stress point. S is
assembled once per system and cached when it takes under a tenth of the free memory
(0.34 GB for 180k P2 DOFs: 28M entries), so a transient's per-step stresses cost one sparse product
instead of recomputing B element by element.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femstudy.fe.assembly import CHUNK, jacobians, strain_matrices
from femstudy.femur_model import REGION_NAMES


def _chunks(n: int):
    for start in range(0, n, CHUNK):
        yield np.arange(start, min(start + CHUNK, n))


def _element_dofs(system, cells: np.ndarray) -> np.ndarray:
    """(n, 3 nbf) DOF numbers of ``cells``, node-major as in :func:`strain_matrices`."""
    return (3 * system.cells[cells][:, :, None] + np.arange(3)).reshape(len(cells), -1)


def stress_operator(system) -> sp.csr_matrix | None:
    """S (n_tets·nq·6, n_dofs) [MPa/mm] with σ = S u, rows ordered (element, point, Voigt
    component); built on first use and cached, or None when it would not fit (see above)."""
    key = ("", "stress-operator")
    if key not in system.cache:
        from femstudy.fe.linsolve import available_memory_bytes

        nq, width = len(system.ref.weights), 3 * system.cells.shape[1]
        rows = system.n_tets * nq * 6
        if rows * width * 16 > 0.1 * available_memory_bytes():  # 12 B per entry, plus building
            system.cache[key] = None
        else:
            data = np.empty((system.n_tets, nq, 6, width))
            for part in _chunks(system.n_tets):
                B, _ = strain_matrices(system, part)
                data[part] = system.materials.D[system.materials.index[part]][:, None] @ B
            dofs = _element_dofs(system, np.arange(system.n_tets)).astype(np.int32)
            columns = np.broadcast_to(dofs[:, None, None, :], data.shape)
            system.cache[key] = sp.csr_matrix((data.ravel(), columns.ravel(),
                                               np.arange(rows + 1, dtype=np.int64) * width),
                                              shape=(rows, system.n_dofs))
    return system.cache[key]


def element_stress(system, u: np.ndarray, cells: np.ndarray | None = None) -> np.ndarray:
    """σ (n, nq, 6) [MPa], Voigt [xx, yy, zz, yz, xz, xy], at the quadrature points of ``cells``."""
    nq = len(system.ref.weights)
    if cells is None and (S := stress_operator(system)) is not None:
        return (S @ u).reshape(system.n_tets, nq, 6)
    cells = np.arange(system.n_tets) if cells is None else np.asarray(cells)
    out = np.empty((len(cells), nq, 6))
    for part in _chunks(len(cells)):
        idx = cells[part]
        B, _ = strain_matrices(system, idx)
        strain = B @ u[_element_dofs(system, idx)][:, None, :, None]
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
    key = ("", "stress-points")
    if key not in system.cache:
        system.cache[key] = quadrature_points(system)
    xq = system.cache[key]
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
    key = ("", "region-nodes")
    if key not in system.cache:
        system.cache[key] = {int(code): (system.region == code, np.unique(system.cells[system.region == code]))
                             for code in np.unique(system.region)}
    regions = {}
    for code, (cells, nodes) in system.cache[key].items():
        regions[REGION_NAMES.get(code, str(code))] = {
            "max_von_mises_MPa": float(vm[cells].max()), "max_deflection_mm": float(magnitude[nodes].max())}
    out["regions"] = regions
    return out
