"""Displacement and stress of a P1/P2 solution at arbitrary points.

Each point is located in a tetrahedron of the system's mesh (:class:`MeshLocator`: VTK's cell
locator through pyvista, checked, and where it misses by round-off on a shared face or the
boundary, the element among the 64 with the nearest centroids and those sharing a vertex with
VTK's in which the point's smallest barycentric coordinate is largest); a point counts as inside when that coordinate is ≥ −1e-9. With ξ the point's
reference coordinates in that element, the displacement is u(x) = Σ_a N_a(ξ) u_a and the
stress σ(x) = D B(ξ) u_e [MPa] — the element's own stress field evaluated at the point
(discontinuous across elements; on a shared face one of the elements is used). Both are
linear in u, so the probe stores them as sparse operators and applies them to any number
of load cases. Points outside the mesh give NaN and are listed in ``outside``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from femstudy.fe.assembly import jacobians

log = logging.getLogger(__name__)

#: Barycentric tolerance for accepting a point in its closest cell.
BOUNDARY_TOLERANCE = 1e-9
#: Points this far outside (in barycentric coordinates) the cell VTK gives are outside the
#: mesh: a point inside lies in its closest cell, on a shared face at worst.
RETRY_WINDOW = 1e-3
#: Voigt rows [xx, yy, zz, yz, xz, xy]: for each row, the (gradient, component) pairs it sums.
_VOIGT = [((0, 0),), ((1, 1),), ((2, 2),), ((2, 1), (1, 2)), ((2, 0), (0, 2)), ((1, 0), (0, 1))]


@dataclass(frozen=True)
class PointProbe:
    """Linear maps from a solution vector to values at points.

    points        : (n, 3) the points [mm]
    element       : (n,) containing tetrahedron (−1 outside the mesh)
    reference     : (n, 3) reference coordinates ξ in that element
    displacement_operator : (3 n_inside, n_dofs) sparse, rows (point, component)
    stress_operator       : (6 n_inside, n_dofs) sparse [MPa/mm], rows (point, Voigt component)
    """

    points: np.ndarray
    element: np.ndarray
    reference: np.ndarray
    displacement_operator: sp.csr_matrix
    stress_operator: sp.csr_matrix

    @property
    def inside(self) -> np.ndarray:
        return self.element >= 0

    @property
    def outside(self) -> np.ndarray:
        """Indices of the points that lie outside the mesh."""
        return np.flatnonzero(self.element < 0)

    def _apply(self, operator, u: np.ndarray, width: int) -> np.ndarray:
        u = np.asarray(u, float)
        values = (operator @ u).reshape((-1, width) + u.shape[1:])
        out = np.full((len(self.points), width) + u.shape[1:], np.nan)
        out[self.inside] = values
        return np.moveaxis(out, 1, -1)

    def displacement(self, u: np.ndarray) -> np.ndarray:
        """(n, 3) displacement [mm] for u (n_dofs,); (n, k, 3) for u (n_dofs, k); NaN outside."""
        return self._apply(self.displacement_operator, u, 3)

    def stress(self, u: np.ndarray) -> np.ndarray:
        """(n, 6) Voigt stress [MPa] for u (n_dofs,); (n, k, 6) for u (n_dofs, k); NaN outside."""
        return self._apply(self.stress_operator, u, 6)


def reference_coordinates(system, element: np.ndarray, points: np.ndarray, inverse: np.ndarray | None = None):
    """ξ (n, 3), J⁻¹ (n, 3, 3) and the smallest barycentric coordinate of each point in ``element``
    (``inverse``: every element's J⁻¹, when already computed)."""
    mesh = system.mesh
    invJ = jacobians(mesh.p.T, mesh.t.T[element])[0] if inverse is None else inverse[element]
    xi = np.einsum("nij,nj->ni", invJ, points - mesh.p.T[mesh.t[0, element]])
    return xi, invJ, np.minimum(1 - xi.sum(axis=1), xi.min(axis=1))


class MeshLocator:
    """Finds the tetrahedron holding each point of a system's mesh; built once, asked many times.

    VTK's static cell locator (through pyvista) answers first (containing cell, else closest
    cell); a point it places just outside its cell (between the tolerance and
    :data:`RETRY_WINDOW`: it happens on shared faces) is tried in the 64 elements with the
    nearest centroids and in those sharing a vertex with VTK's cell (an element with long
    edges can hold a point while its centroid is farther than 64 others).
    """

    def __init__(self, system):
        import pyvista as pv

        self.system = system
        self._grid = pv.UnstructuredGrid({pv.CellType.TETRA: system.mesh.t.T}, system.mesh.p.T)
        self._centroids = None
        self._vertex_elements = None
        self._inverse = jacobians(system.mesh.p.T, system.mesh.t.T)[0]  # J⁻¹ of every element, for all queries

    def locate(self, points: np.ndarray, search_missed: bool = True):
        """Containing element (−1 if none), reference coordinates ξ and J⁻¹ of every point (n, 3) [mm]
        (NaN where no element was tried). ``search_missed=False`` skips the closest-cell search for
        the points VTK finds in no cell, which only rescues points on the boundary to round-off:
        they are then outside (the quick test of :meth:`inside`)."""
        from scipy.spatial import cKDTree

        mesh = self.system.mesh
        element = np.asarray(self._grid.find_containing_cell(points), dtype=np.int64).reshape(-1)
        missed = element < 0
        if search_missed and missed.any():
            element[missed] = np.asarray(self._grid.find_closest_cell(points[missed]), dtype=np.int64)
        n = len(element)
        xi, invJ, worst = np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan), np.full(n, -np.inf)
        tried = np.flatnonzero(element >= 0)
        if len(tried):
            xi[tried], invJ[tried], worst[tried] = self._coordinates(element[tried], points[tried])
        retry = np.flatnonzero((worst < -BOUNDARY_TOLERANCE) & (worst > -RETRY_WINDOW))
        if len(retry):
            if self._centroids is None:
                self._centroids = cKDTree(mesh.p[:, mesh.t].mean(axis=1).T)
            k = min(64, mesh.nelements)
            near = np.hstack([self._centroids.query(points[retry], k)[1].reshape(len(retry), k),
                              self._sharing_a_vertex(element[retry])])
            tries = self._coordinates(np.maximum(near, 0).ravel(), np.repeat(points[retry], near.shape[1], axis=0))[2]
            tries = np.where(near.ravel() >= 0, tries, -np.inf)
            best = np.argmax(tries.reshape(near.shape), axis=1)
            element[retry] = near[np.arange(len(retry)), best]
            xi[retry], invJ[retry], worst[retry] = self._coordinates(element[retry], points[retry])
        element[worst < -BOUNDARY_TOLERANCE] = -1
        return element, xi, invJ

    def _sharing_a_vertex(self, element: np.ndarray) -> np.ndarray:
        """(n, m) the elements sharing a vertex with each element (rows padded with −1)."""
        mesh = self.system.mesh
        if self._vertex_elements is None:
            vertex = mesh.t.T.ravel()
            order = np.argsort(vertex, kind="stable")
            self._vertex_elements = (np.searchsorted(vertex[order], np.arange(mesh.p.shape[1] + 1)),
                                     np.repeat(np.arange(mesh.nelements), 4)[order])
        start, owners = self._vertex_elements
        found = [np.unique(np.concatenate([owners[start[v]:start[v + 1]] for v in mesh.t[:, e]])) for e in element]
        out = np.full((len(found), max(map(len, found))), -1, dtype=np.int64)
        for row, elements in enumerate(found):
            out[row, :len(elements)] = elements
        return out

    def _coordinates(self, element: np.ndarray, points: np.ndarray):
        return reference_coordinates(self.system, element, points, self._inverse)

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n,) the cell nearest each point (n, 3) [mm] and (n, 3) the nearest point on it."""
        cell, nearest = self._grid.find_closest_cell(np.atleast_2d(points), return_closest_point=True)
        return np.asarray(cell, dtype=np.int64).reshape(-1), np.asarray(nearest, float).reshape(-1, 3)

    def label(self, points: np.ndarray) -> np.ndarray:
        """(n,) region code of the element holding each point (n, 3) [mm], −1 outside the mesh:
        :meth:`locate` without its closest-cell search, quicker for the many points of a
        bisection. VTK's containing cell alone is not enough: its tolerance accepts points just
        outside the mesh."""
        element = self.locate(np.atleast_2d(np.asarray(points, float)), search_missed=False)[0]
        return np.where(element >= 0, self.system.region[np.maximum(element, 0)], -1)


def point_probe(system, points: np.ndarray, element: np.ndarray | None = None,
                locator: MeshLocator | None = None) -> PointProbe:
    """Locate ``points`` in the system's mesh and build the point operators.

    Parameters
    ----------
    system : :class:`femstudy.fe.FESystem` (P1 or P2)
    points : (n, 3) points [mm]
    element : (n,) optional, the element of each point, used as given (its fields are
        extended polynomially to a point just outside it) instead of locating the points
    locator : :class:`MeshLocator` of ``system``, to reuse one already built

    Returns
    -------
    :class:`PointProbe`

    Examples
    --------
    >>> p = point_probe(system, np.array([[1.0, 2.0, 0.5]]))  # doctest: +SKIP
    >>> p.stress(u)[0]  # σxx, σyy, σzz, σyz, σxz, σxy [MPa]  # doctest: +SKIP
    """
    points = np.atleast_2d(np.asarray(points, float))
    if element is None:
        element, xi, invJ = (locator or MeshLocator(system)).locate(points)
    else:
        element = np.asarray(element, dtype=np.int64)
        xi, invJ, _ = reference_coordinates(system, element, points)
    inside = element >= 0
    if (~inside).any():
        log.debug("%d of %d probe points lie outside the mesh", np.sum(~inside), len(points))
    e, xi, invJ = element[inside], xi[inside], invJ[inside]
    ref = system.ref
    nbf = ref.nbf
    X = xi.T
    N = np.stack([ref.element.lbasis(X, a)[0] for a in range(nbf)], axis=1)  # (n, nbf)
    dN = np.stack([ref.element.lbasis(X, a)[1] for a in range(nbf)], axis=1).transpose(2, 1, 0)  # (n, nbf, 3)
    G = np.einsum("nak,nkj->naj", dN, invJ)  # ∂N_a/∂x_j
    n = len(e)
    B = np.zeros((n, 6, nbf, 3))
    for row, pairs in enumerate(_VOIGT):
        for gradient, component in pairs:
            B[:, row, :, component] = G[:, :, gradient]
    D = system.materials.D[system.materials.index[e]]
    DB = (D @ B.reshape(n, 6, 3 * nbf)).reshape(n * 6, 3 * nbf)
    dofs = (3 * system.cells[e][:, :, None] + np.arange(3)).reshape(n, 3 * nbf)
    stress = sp.csr_matrix((DB.ravel(), np.repeat(dofs, 6, axis=0).ravel(),
                            np.arange(6 * n + 1) * 3 * nbf), shape=(6 * n, system.n_dofs))
    Nu = np.zeros((n, 3, nbf, 3))
    for c in range(3):
        Nu[:, c, :, c] = N
    displacement = sp.csr_matrix((Nu.reshape(-1).copy(), np.repeat(dofs, 3, axis=0).ravel(),
                                  np.arange(3 * n + 1) * 3 * nbf), shape=(3 * n, system.n_dofs))
    ref_coords = np.full((len(points), 3), np.nan)
    ref_coords[inside] = xi
    return PointProbe(points, element, ref_coords, displacement, stress)
