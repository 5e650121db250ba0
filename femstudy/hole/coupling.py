"""The submodel's boundary data: global displacements at the local model's cut-face nodes.

Each cut-face node (vertices and P2 mid-nodes of the ``cut_lateral`` and ``cut_bottom`` faces)
is located in the global mesh by :func:`femstudy.hole.probe.point_probe` and takes the global
field's value there, u(x) = Σ_a N_a(ξ) u_a. A node just outside the global mesh takes the
value of its closest cell's field at its closest point on the global mesh; farther than
``tolerance_mm`` away it is a user error (the submodel leaves the bone). The default
(:func:`default_tolerance_mm`) is the larger of 2 mm and half the median edge of the cut faces'
elements or of the global cells the nodes go to: a node that close takes a field that varies
over half an element by no more than the local mesh's own interpolation does there, 8 mm from
the hole (Saint-Venant), whereas a submodel that leaves the bone by more than half an element
is refused. Coarse levels of the run's verification move nodes by more than a fixed 2 mm: 2.8
mm on the 16 mm built-in femur at refinement 0.4 (11 mm cut edges) and 2.1 mm on TLEM 2 at
8 mm, refinement 0.53; both were refused, leaving their measures without verdicts. Nodes leave
the global mesh by round-off on the surface facets the local top is ray-cast on, where P2
mid-nodes of the local top's chords cut under curved facets, and where a column's bottom jumps
between neighbours (a ray grazing the canal: the cells between them bridge the canal's
edge) — up to 1.3 mm on the built-in femur at refinement 0.5, 0.25 mm at refinement 1, at
the cut, 8 mm from the hole; ``moved_mm`` reports the largest move. Units: mm.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from femstudy.errors import require
from femstudy.hole.dirichlet import facet_indices, facet_nodes, node_dofs
from femstudy.hole.probe import MeshLocator, point_probe

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CutBoundary:
    """The prescribed DOFs of a station and the global fields there.

    dofs   : (3 m,) sorted DOF numbers of the m cut-face nodes (x, y, z per node)
    values : (3 m, k) their displacements [mm] for each of the k global fields
    moved_mm : largest distance a node was moved onto the global mesh [mm] (0: none)
    """

    dofs: np.ndarray
    values: np.ndarray
    moved_mm: float


#: the smallest tolerance for a cut node outside the global mesh [mm]
MIN_TOLERANCE_MM = 2.0


def median_edge_mm(points: np.ndarray, simplices: np.ndarray) -> float:
    """Median edge length [mm] of the simplices (k, n) (triangles or tetrahedra) over ``points`` (3, m).

    Examples
    --------
    >>> median_edge_mm(np.eye(3) * 4.0, np.array([[0], [1], [2]]))  # an equilateral triangle
    5.656854249492381
    """
    k = simplices.shape[0]
    lengths = [np.linalg.norm(points[:, simplices[a]] - points[:, simplices[b]], axis=0)
               for a in range(k) for b in range(a + 1, k)]
    return float(np.median(np.concatenate(lengths)))


def default_tolerance_mm(*edges_mm: float) -> float:
    """max(:data:`MIN_TOLERANCE_MM`, ½ of the largest of ``edges_mm``) [mm] (module docstring).

    Examples
    --------
    >>> default_tolerance_mm(3.0, 11.4)
    5.7
    """
    return max(MIN_TOLERANCE_MM, 0.5 * max(edges_mm))


def cut_boundary(global_system, fields: np.ndarray, local_system, station, tolerance_mm: float | None = None,
                 locator: MeshLocator | None = None) -> CutBoundary:
    """Global displacement fields at the cut-face nodes of a station's local model.

    Parameters
    ----------
    global_system : :class:`femstudy.fe.FESystem` of the femur (no hole)
    fields : (n_dofs_global, k) global displacement fields [mm]
    local_system : :class:`femstudy.fe.FESystem` assembled on ``station.mesh``
    station : :class:`femstudy.hole.mesh.HoleStation`
    tolerance_mm : how far outside the global mesh a cut node may lie [mm]; by default
        :func:`default_tolerance_mm` of the cut faces' elements and the global cells reached
    locator : :class:`~femstudy.hole.probe.MeshLocator` of ``global_system``, to reuse one built
        for several stations

    Returns
    -------
    CutBoundary

    Examples
    --------
    >>> cut = cut_boundary(system, unit_fields, local, station)        # doctest: +SKIP
    >>> u = factorize_prescribed(local, cut.dofs).solve(cut.values)  # doctest: +SKIP
    """
    fields = np.asarray(fields, float).reshape(global_system.n_dofs, -1)
    nodes = facet_nodes(local_system, facet_indices(local_system, station.cut_faces))
    points = local_system.nodes[nodes].copy()
    locator = locator or MeshLocator(global_system)
    probe = point_probe(global_system, points, locator=locator)
    moved = 0.0
    outside = probe.outside
    element = probe.element.copy()
    if len(outside):
        cell, nearest = locator.closest(points[outside])
        distance = np.linalg.norm(nearest - points[outside], axis=1)
        moved = float(distance.max())
        if tolerance_mm is None:
            cut_facets = local_system.mesh.facets[:, facet_indices(local_system, station.cut_faces)]
            global_mesh = global_system.mesh
            tolerance_mm = default_tolerance_mm(median_edge_mm(local_system.mesh.p, cut_facets),
                                                median_edge_mm(global_mesh.p, global_mesh.t[:4, np.unique(cell)]))
        require(moved <= tolerance_mm, f"the local model's cut boundary reaches {moved:.2f} mm outside the femur "
                                       f"mesh (more than {tolerance_mm:.3g} mm): reduce the submodel radius or depth cap")
        points[outside], element[outside] = nearest, cell
        log.info("%d of %d cut nodes moved onto the femur mesh (at most %.3g mm)", len(outside), len(points), moved)
        probe = point_probe(global_system, points, element)
    values = probe.displacement(fields)  # (m, k, 3)
    values = np.moveaxis(values, -1, 1).reshape(3 * len(nodes), -1)  # rows (node, component)
    return CutBoundary(node_dofs(nodes).ravel(), values, moved)
