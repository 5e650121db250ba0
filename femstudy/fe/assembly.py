"""Stiffness and mass matrices of linear elasticity on a tetrahedral mesh (P1 or P2).

K u = f with K = Σ_e ∫_e Bᵀ D B dV [N/mm] and the consistent mass M = Σ_e ∫_e ρ Nᵀ N dV
[tonne], in mm, N, MPa, s, tonne/mm³. scikit-fem supplies the element (ElementTetP1/P2), its
quadrature and the degree-of-freedom numbering; the element integrals are evaluated here as
batched matrix products over all elements at once, which is several times faster than a
generic per-entry :class:`skfem.BilinearForm` (docs/solver.md has the timings; the tests
check both give the same matrices to round-off).

DOF numbering is scikit-fem's for ``ElementVector``: node n (the mesh vertices, then for P2
the edge mid-points in ``mesh.edges`` order) carries DOFs 3n, 3n+1, 3n+2 (x, y, z), so K and
M are assembled as 3×3-block sparse matrices over the nodes' sparsity pattern.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import skfem
from skfem.quadrature import get_quadrature

from femstudy.errors import require
from femstudy.fe.materials import ElementMaterials, element_materials
from femstudy.femur_mesh import TetMesh
from femstudy.materials import BoneMaterials

log = logging.getLogger(__name__)

#: Elements per batch: bounds the temporary arrays to a few hundred MB at any mesh size.
CHUNK = 20_000


@dataclass(frozen=True)
class Reference:
    """The reference element: shape functions at the quadrature points.

    stiffness rule: exact for ∇N·∇N (degree 2(p−1)); mass rule: exact for N·N (degree 2p).
    grad   : (nq, nbf, 3) ∂N_a/∂ξ at the stiffness points; weights (nq,) sum to 1/6
    mass   : (nbf, nbf) ∫_ref N_a N_b dξ
    """

    order: int
    element: skfem.Element
    points: np.ndarray
    weights: np.ndarray
    grad: np.ndarray
    mass: np.ndarray

    @property
    def nbf(self) -> int:
        return self.grad.shape[1]


def reference(order: int) -> Reference:
    require(order in (1, 2), f"element order must be 1 or 2, got {order}")
    element = skfem.ElementTetP2() if order == 2 else skfem.ElementTetP1()
    nbf = 10 if order == 2 else 4
    X, W = get_quadrature(element, max(2 * (order - 1), 1))
    grad = np.stack([element.lbasis(X, a)[1] for a in range(nbf)]).transpose(2, 0, 1)
    Xm, Wm = get_quadrature(element, 2 * order)
    N = np.stack([element.lbasis(Xm, a)[0] for a in range(nbf)])
    return Reference(order, element, X, W, grad, (N * Wm) @ N.T)


@dataclass(frozen=True, eq=False)
class FESystem:
    """An assembled elasticity model; build it with :func:`assemble`, reuse it for every load
    and constraint set (:func:`femstudy.fe.factorize` factorises it for one set of clamps).

    mesh         : scikit-fem MeshTet of the used vertices [mm]
    nodes        : (n_nodes, 3) node coordinates [mm] (vertices, then P2 edge mid-points)
    cells        : (n_tets, nbf) node indices of every element, scikit-fem's local order
    region       : (n_tets,) region code per element
    K, M         : (3 n_nodes)² CSR stiffness [N/mm] and consistent mass [tonne]; they share
                   one sparsity pattern (M keeps explicit zeros), so K + c M is an array sum
    M_nodes      : (n_nodes)² CSR scalar mass [tonne]: M = M_nodes ⊗ I₃, so M u is
                   ``M_nodes @ u.reshape(-1, 3)`` with a ninth of the entries
    point_index  : for every point of the input TetMesh, its mesh vertex (−1 if unused)
    timings      : wall times [s] of the assembly phases
    """

    mesh: skfem.MeshTet
    ref: Reference
    dofs: skfem.assembly.Dofs
    nodes: np.ndarray
    cells: np.ndarray
    region: np.ndarray
    materials: ElementMaterials
    K: sp.csr_matrix
    M: sp.csr_matrix
    point_index: np.ndarray
    M_nodes: sp.csr_matrix
    timings: dict = field(default_factory=dict)

    @property
    def order(self) -> int:
        return self.ref.order

    @property
    def n_dofs(self) -> int:
        return 3 * len(self.nodes)

    @property
    def n_tets(self) -> int:
        return len(self.cells)

    def summary(self) -> str:
        t = self.timings
        return (f"P{self.order} mesh: {self.n_tets:,} tets, {len(self.nodes):,} nodes, {self.n_dofs:,} DOFs; "
                f"pattern {t['pattern_s']:.2f} s, element matrices {t['elements_s']:.2f} s, "
                f"K and M {t['matrices_s']:.2f} s")


def jacobians(points: np.ndarray, tets: np.ndarray):
    """Affine maps x = p0 + J ξ of the tets: (J⁻¹ (n, 3, 3), det J (n,))."""
    p = points[tets]
    J = (p[:, 1:] - p[:, :1]).transpose(0, 2, 1)
    det = np.linalg.det(J)
    require(np.all(np.abs(det) > 1e-12 * np.abs(J).max() ** 3),
            f"the mesh has {np.sum(np.abs(det) <= 1e-12 * np.abs(J).max() ** 3)} degenerate (flat) tetrahedra")
    return np.linalg.inv(J), det


def strain_matrices(mesh: skfem.MeshTet, ref: Reference, cells: np.ndarray):
    """B (n, nq, 6, 3 nbf) with ε = B u_e (Voigt, engineering shear) at the stiffness
    quadrature points of ``ref``, and the integration weights dV (n, nq) [mm³], for elements
    ``cells`` of ``mesh``."""
    invJ, det = jacobians(mesh.p.T, mesh.t.T[cells])
    G = np.einsum("qak,ekj->eqaj", ref.grad, invJ)  # ∂N_a/∂x_j = Σ_k ∂N_a/∂ξ_k (J⁻¹)_kj
    n, nq, nbf = G.shape[:3]
    B = np.zeros((n, nq, 6, nbf, 3))
    for c in range(3):
        B[:, :, c, :, c] = G[..., c]
    for row, (i, j) in zip((3, 4, 5), ((1, 2), (0, 2), (0, 1))):
        B[:, :, row, :, i] = G[..., j]
        B[:, :, row, :, j] = G[..., i]
    return B.reshape(n, nq, 6, 3 * nbf), np.abs(det)[:, None] * ref.weights


def _node_pattern(cells: np.ndarray, n_nodes: int):
    """Node-level CSR pattern (indptr, indices) and, for every (element, a, b) entry, the
    position of the pair (cells[e, a], cells[e, b]) in it."""
    nbf = cells.shape[1]
    rows = np.repeat(cells, nbf, axis=1).ravel()
    cols = np.tile(cells, (1, nbf)).ravel()
    pattern = sp.csr_matrix((np.ones(len(rows), np.float32), (rows, cols)), shape=(n_nodes, n_nodes))
    pattern.sum_duplicates()
    keys = np.repeat(np.arange(n_nodes, dtype=np.int64), np.diff(pattern.indptr)) * n_nodes + pattern.indices
    position = np.searchsorted(keys, rows.astype(np.int64) * n_nodes + cols).astype(np.int32)
    return pattern.indptr, pattern.indices, position.reshape(len(cells), nbf * nbf)


#: Above this many distinct stiffness matrices (one per element with a per-element cortical
#: axis) D B is formed element by element instead of one matrix product per material.
GROUPED_MAX = 16


def _stress_matrices(B: np.ndarray, D: np.ndarray, index: np.ndarray) -> np.ndarray:
    """D B (n, nq, 6, m) for strain matrices B (n, nq, 6, m) and element stiffnesses D[index]."""
    if len(D) > GROUPED_MAX:
        return D[index][:, None] @ B
    n, nq, _, m = B.shape
    DB = np.empty_like(B)
    for k in np.unique(index):
        sel = index == k
        columns = B[sel].transpose(0, 1, 3, 2).reshape(-1, 6)  # all (element, point, column) at once
        DB[sel] = (columns @ D[k].T).reshape(-1, nq, m, 6).transpose(0, 1, 3, 2)
    return DB


def _block_matrix(blocks: np.ndarray, indptr, indices, n_nodes: int) -> sp.csr_matrix:
    return sp.bsr_matrix((blocks, indices, indptr), shape=(3 * n_nodes, 3 * n_nodes)).tocsr()


def assemble(mesh: TetMesh, materials: BoneMaterials | None = None, order: int = 2,
             long_axis=None) -> FESystem:
    """Assemble the stiffness K [N/mm] and consistent mass M [tonne] of a region-marked mesh.

    Parameters
    ----------
    mesh : TetMesh
        Points [mm], tetrahedra and region codes (:mod:`femstudy.femur_mesh`).
    materials : BoneMaterials, optional
        Cortical and cancellous materials; default thesis Table 3-1.
    order : {2, 1}
        Quadratic (10-node) or linear tetrahedra.
    long_axis : array_like, optional
        The bone's long axis for a transversely isotropic cortex: a 3-vector, one per tet,
        or None for the principal axis of the mesh points (largest spread).

    Returns
    -------
    FESystem

    Examples
    --------
    >>> from femstudy.fe.geometry import tube_mesh
    >>> system = assemble(tube_mesh(100.0, 14.0, 6.5, 1, 12, 10), order=1)
    >>> system.n_dofs
    792
    """
    materials = BoneMaterials() if materials is None else materials
    t0 = time.perf_counter()
    points, tets = np.asarray(mesh.points, float), np.asarray(mesh.tets)
    require(points.ndim == 2 and points.shape[1] == 3 and tets.ndim == 2 and tets.shape[1] == 4 and len(tets),
            "the mesh needs (n, 3) points and a non-empty (m, 4) array of tetrahedra")
    used = np.unique(tets)
    point_index = np.full(len(points), -1, dtype=np.int64)
    point_index[used] = np.arange(len(used))
    skmesh = skfem.MeshTet(np.ascontiguousarray(points[used].T), np.ascontiguousarray(point_index[tets].T))
    ref = reference(order)
    if long_axis is None and materials.cortical_model == "transversely_isotropic":
        centred = skmesh.p.T - skmesh.p.mean(axis=1)
        long_axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    mats = element_materials(mesh.region, materials, long_axis)
    scalar = skfem.assembly.Dofs(skmesh, ref.element)
    cells = np.ascontiguousarray(scalar.element_dofs.T)
    nodes = skmesh.p.T if order == 1 else np.concatenate([skmesh.p.T, skmesh.p.T[skmesh.edges].mean(axis=0)])
    dofs = skfem.assembly.Dofs(skmesh, skfem.ElementVector(ref.element))
    n_nodes = len(nodes)
    t1 = time.perf_counter()
    indptr, indices, position = _node_pattern(cells, n_nodes)
    t2 = time.perf_counter()

    nbf, nnzb = ref.nbf, len(indices)
    blocks, nodal_mass = np.zeros((nnzb, 9)), np.zeros(nnzb)
    for start in range(0, len(cells), CHUNK):
        part = np.arange(start, min(start + CHUNK, len(cells)))
        n, pairs = len(part), len(part) * nbf * nbf
        B, dV = strain_matrices(skmesh, ref, part)
        DB = _stress_matrices(B, mats.D, mats.index[part]) * dV[..., None, None]
        Ke = B.reshape(n, -1, 3 * nbf).transpose(0, 2, 1) @ DB.reshape(n, -1, 3 * nbf)  # rows (a, c), cols (b, d)
        Me = (mats.density[part] * 6 * dV.sum(axis=1))[:, None, None] * ref.mass  # 6 ΣdV = |det J|
        # every element's (a, b) entries go to its node pair's block: a product with a 0/1
        # matrix, one column per (element, a, b), several times faster than np.bincount here
        scatter = sp.csc_matrix((np.ones(pairs), position[part].ravel(), np.arange(pairs + 1)), shape=(nnzb, pairs))
        blocks += scatter @ Ke.reshape(n, nbf, 3, nbf, 3).transpose(0, 1, 3, 2, 4).reshape(pairs, 9)
        nodal_mass += scatter @ Me.ravel()
    t3 = time.perf_counter()
    K = _block_matrix(blocks.reshape(nnzb, 3, 3), indptr, indices, n_nodes)
    del blocks
    M_nodes = sp.csr_matrix((nodal_mass, indices, indptr), shape=(n_nodes, n_nodes))
    M = _block_matrix(nodal_mass[:, None, None] * np.eye(3), indptr, indices, n_nodes)
    t4 = time.perf_counter()
    timings = {"setup_s": t1 - t0, "pattern_s": t2 - t1, "elements_s": t3 - t2, "matrices_s": t4 - t3,
               "total_s": t4 - t0}
    system = FESystem(skmesh, ref, dofs, nodes, cells, np.asarray(mesh.region), mats, K, M, point_index,
                      M_nodes, timings)
    log.info("assembled %s", system.summary())
    return system
