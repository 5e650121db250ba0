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

import contextlib
import logging
import os
import time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import skfem
from skfem.quadrature import get_quadrature

from femstudy.errors import require
from femstudy.fe.materials import ElementMaterials, element_materials, stiffness_tensor
from femstudy.femur_mesh import TetMesh
from femstudy.materials import BoneMaterials

log = logging.getLogger(__name__)

#: Fewest elements per batch. A batch's scatter returns a full-size array of the pattern's
#: blocks, so a fine mesh takes batches of as many element blocks as the pattern has (its
#: temporaries about twice K's size): on the 3.5 mm femur (5.9M blocks) the element loop took
#: 4.1 s in batches of 20,000 and 3.1 s in batches of 58,942; at 16 mm nothing changes.
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
    K_blocks     : the stiffness [N/mm] as it is assembled: BSR of 3×3 node blocks on the node
                   pattern (what a static solve restricts and factorises, with no conversion)
    K, M         : (3 n_nodes)² CSR stiffness [N/mm] and consistent mass [tonne]; they share
                   one sparsity pattern (both keep their blocks' explicit zeros), so K + c M is
                   an array sum. Each is formed when first asked for (a static solve needs neither)
    M_nodes      : (n_nodes)² CSR scalar mass [tonne]: M = M_nodes ⊗ I₃, so M u is
                   ``M_nodes @ u.reshape(-1, 3)`` with a ninth of the entries
    dofs         : scikit-fem's vector DOF numbering (node n carries 3n…3n+2), made when asked for
    point_index  : for every point of the input TetMesh, its mesh vertex (−1 if unused)
    timings      : wall times [s] of the assembly phases
    """

    mesh: skfem.MeshTet
    ref: Reference
    nodes: np.ndarray
    cells: np.ndarray
    region: np.ndarray
    materials: ElementMaterials
    K_blocks: sp.bsr_matrix
    point_index: np.ndarray
    M_nodes: sp.csr_matrix
    timings: dict[str, float] = field(default_factory=dict)

    @cached_property
    def K(self) -> sp.csr_matrix:
        return self.K_blocks.tocsr()

    @cached_property
    def M(self) -> sp.csr_matrix:
        n_nodes = len(self.nodes)
        return _blocks(self.M_nodes.data[:, None, None] * np.eye(3), self.M_nodes.indptr,
                       self.M_nodes.indices, n_nodes).tocsr()

    @cached_property
    def dofs(self) -> skfem.assembly.Dofs:
        return skfem.assembly.Dofs(self.mesh, skfem.ElementVector(self.ref.element))

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


def _node_pattern(cells: np.ndarray, n_nodes: int):
    """Node-level CSR pattern (indptr, indices) and, for every (element, a, b) entry, the
    position of the pair (cells[e, a], cells[e, b]) in it.

    Row r lists, for every element corner (e, a) at node r, the element's nodes; each entry
    carries its pair number (e nbf + a) nbf + b. Sorting the rows (scipy's per-row sort, which
    carries the numbers along) puts equal columns side by side, so a running count of new
    columns gives every pair its position: no search over the whole pattern.
    """
    n, nbf = cells.shape
    corners = np.argsort(cells.ravel(), kind="stable")            # (e, a) = divmod(corner, nbf), by node
    counts = np.bincount(cells.ravel(), minlength=n_nodes) * nbf
    require(np.all(counts > 0), "every node must belong to an element")
    rows = np.concatenate([[0], np.cumsum(counts)])
    pairs = (corners[:, None] * nbf + np.arange(nbf)).ravel()
    listed = sp.csr_matrix((pairs, cells[corners // nbf].ravel(), rows), shape=(n_nodes, n_nodes))
    listed.has_sorted_indices = False
    listed.sort_indices()
    new = np.empty(len(pairs), bool)
    new[0], new[1:] = True, listed.indices[1:] != listed.indices[:-1]
    new[rows[:-1]] = True
    running = np.cumsum(new) - 1
    position = np.empty(len(pairs), np.int32)
    position[listed.data] = running
    indptr = np.concatenate([[0], running[rows[1:] - 1] + 1])
    return indptr, listed.indices[new], position.reshape(n, nbf * nbf)


def reference_stiffness(ref: Reference) -> np.ndarray:
    """S[(a, b), (m, p)] = ∫_ref ∂N_a/∂ξ_m ∂N_b/∂ξ_p dξ, (nbf², 9): exact on the stiffness rule."""
    S = np.einsum("q,qam,qbp->abmp", ref.weights, ref.grad, ref.grad)
    return S.reshape(ref.nbf ** 2, 9)


def element_stiffness(S: np.ndarray, invJ: np.ndarray, det: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Element stiffnesses as 3×3 node blocks (n, nbf², 9) [N/mm], block (a, b) row-major in (i, j).

    With ∂N_a/∂x_k = Σ_m ∂N_a/∂ξ_m J⁻¹_mk on an affine tet,

        K_e[(a, i), (b, j)] = ∫ ∂N_a/∂x_k C_ikjl ∂N_b/∂x_l dV = Σ_mp S[(a, b), (m, p)] Ĉ[(m, p), (i, j)],
        Ĉ_mpij = |det J| Σ_kl J⁻¹_mk C_ikjl J⁻¹_pl,

    the elasticity tensor C (n, 3, 3, 3, 3) [MPa] pulled back to the reference element: one
    (nbf² × 9) @ (9 × 9) product per element instead of Bᵀ D B at every quadrature point.
    """
    n = len(invJ)
    A = invJ @ C.transpose(0, 2, 1, 3, 4).reshape(n, 3, 27)          # [e, m, (i, j, l)]: Σ_k J⁻¹_mk C_ikjl
    A = A.reshape(n, 27, 3) @ invJ.transpose(0, 2, 1)                 # [e, (m, i, j), p]: Σ_l … J⁻¹_pl
    C_ref = A.reshape(n, 3, 3, 3, 3).transpose(0, 1, 4, 2, 3).reshape(n, 9, 9) * np.abs(det)[:, None, None]
    return S @ C_ref


def _blocks(blocks: np.ndarray, indptr, indices, n_nodes: int) -> sp.bsr_matrix:
    matrix = sp.bsr_matrix((blocks, indices, indptr), shape=(3 * n_nodes, 3 * n_nodes))
    matrix.has_sorted_indices = True  # the node pattern's rows are sorted
    return matrix


@contextlib.contextmanager
def small_pages():
    """Within the block, numpy does not advise huge pages for its large arrays (unless the user
    chose with ``NUMPY_MADVISE_HUGEPAGE``). Where the kernel compacts memory on demand for
    advised regions (transparent huge pages with defrag "madvise", as on the benchmark
    machine), first touching the assembly's arrays took 0.4-1.1 s on the 16 mm femur, varying
    from process to process, against a steady 0.6 s without the advice (bench/RESULTS.md)."""
    advise = getattr(getattr(getattr(np, "_core", None), "multiarray", None), "_set_madvise_hugepage", None)
    if advise is None or "NUMPY_MADVISE_HUGEPAGE" in os.environ:
        yield
        return
    before = advise(False)
    try:
        yield
    finally:
        advise(before)


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
    with small_pages():
        return _assemble(mesh, BoneMaterials() if materials is None else materials, order, long_axis)


def _assemble(mesh: TetMesh, materials: BoneMaterials, order: int, long_axis) -> FESystem:
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
    n_nodes = len(nodes)
    t1 = time.perf_counter()
    indptr, indices, position = _node_pattern(cells, n_nodes)
    t2 = time.perf_counter()

    nbf, nnzb = ref.nbf, len(indices)
    S = reference_stiffness(ref)
    C = stiffness_tensor(mats.D)
    blocks, nodal_mass = np.zeros((nnzb, 9)), np.zeros(nnzb)
    batch = max(CHUNK, nnzb // nbf ** 2)
    for start in range(0, len(cells), batch):
        part = np.arange(start, min(start + batch, len(cells)))
        pairs = len(part) * nbf * nbf
        invJ, det = jacobians(skmesh.p.T, skmesh.t.T[part])
        Ke = element_stiffness(S, invJ, det, C[mats.index[part]])
        Me = (mats.density[part] * np.abs(det))[:, None, None] * ref.mass
        # every element's (a, b) entries go to its node pair's block: a product with a 0/1
        # matrix, one column per (element, a, b), several times faster than np.bincount here
        scatter = sp.csc_matrix((np.ones(pairs), position[part].ravel(), np.arange(pairs + 1)), shape=(nnzb, pairs))
        blocks += scatter @ Ke.reshape(pairs, 9)
        nodal_mass += scatter @ Me.ravel()
    t3 = time.perf_counter()
    K_blocks = _blocks(blocks.reshape(nnzb, 3, 3), indptr, indices, n_nodes)
    M_nodes = sp.csr_matrix((nodal_mass, indices, indptr), shape=(n_nodes, n_nodes))
    t4 = time.perf_counter()
    timings = {"setup_s": t1 - t0, "pattern_s": t2 - t1, "elements_s": t3 - t2, "matrices_s": t4 - t3,
               "total_s": t4 - t0}
    system = FESystem(skmesh, ref, nodes, cells, np.asarray(mesh.region), mats, K_blocks, point_index,
                      M_nodes, timings)
    log.info("assembled %s", system.summary())
    return system
