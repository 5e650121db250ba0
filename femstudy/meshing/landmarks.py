"""Clamps at both ends and the drill site on a region-marked tet mesh.

Clamps: the outer-surface nodes within ``clamps.length_mm`` of each end, measured along the
long axis from the extreme surface point (the thesis clamps both ends, §3.3.2).

Drill site: the site's level is at fraction ``position`` of the length from the proximal end;
the drill comes from the side named by ``direction`` (``"anterior"`` enters the anterior
cortex and travels posteriorly; a vector names the entry side the same way, pointing from
the bone towards the drill). The entry point is where a ray from outside towards the shaft
centreline first meets the mesh's outer surface; the outward normal there is the
area-weighted mean of the boundary facet normals within the drill radius; the cortical
thickness is the length of the drill axis inside cortical tets before it first leaves them.
"""

from __future__ import annotations

import numpy as np

from femstudy.errors import UserError
from femstudy.femur_mesh import CORTICAL, Clamps, DrillSite, TetMesh
from femstudy.meshing.frame import Frame
from femstudy.meshing.ray_cells import cells_along


def _faces(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every tet's four faces (4m, 3), ordered so their normals point out of it, the tet owning
    each, and for each the index of its distinct face and that distinct face's count (1 or 2)."""
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    # a sorted face (a, b, c) as the one number (a n + b) n + c orders faces as rows would, and
    # np.unique is ~10x faster on such keys than on rows (the rows themselves past 2²¹ points)
    n = np.int64(faces.max()) + 1
    rows = np.sort(faces, axis=1).astype(np.int64)
    keys = (rows[:, 0] * n + rows[:, 1]) * n + rows[:, 2] if n < 2 ** 21 else rows
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    return faces, np.tile(np.arange(len(tets)), 4), inverse.ravel(), counts


def boundary_faces(mesh: TetMesh) -> np.ndarray:
    """Faces (k, 3) belonging to exactly one tet, ordered so their normals point outwards."""
    faces, _, inverse, counts = _faces(mesh.tets)
    return faces[counts[inverse] == 1]


def region_interface(mesh: TetMesh, code: int = CORTICAL) -> tuple[np.ndarray, np.ndarray]:
    """Faces (k, 3) shared by a tet of region ``code`` and a tet of another region, and (k,)
    that other region's code (the cortex's inner surface against cancellous bone)."""
    faces, owner, inverse, counts = _faces(mesh.tets)
    order = np.argsort(inverse, kind="stable")
    pairs = order[counts[inverse[order]] == 2].reshape(-1, 2)  # the two sides of every inner face
    a, b = mesh.region[owner[pairs[:, 0]]], mesh.region[owner[pairs[:, 1]]]
    first = (a == code) & (b != code)
    second = (b == code) & (a != code)
    return (np.concatenate([faces[pairs[first, 0]], faces[pairs[second, 1]]]),
            np.concatenate([b[first], a[second]]))


def outer_faces(mesh: TetMesh, frame: Frame) -> np.ndarray:
    """Boundary faces on the periosteal surface (the connected boundary piece farthest out).

    The boundary has two pieces, the outer surface and the canal wall; the outer one is the
    piece that contains the point with the largest coordinate along the long axis.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = boundary_faces(mesh)
    n = mesh.n_points
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    on = np.unique(faces)
    top = on[np.argmax(mesh.points[on] @ frame.up)]
    return faces[labels[faces[:, 0]] == labels[top]]


def clamps(mesh: TetMesh, frame: Frame, faces_outer: np.ndarray, length_mm: float) -> Clamps:
    """Outer-surface nodes within ``length_mm`` of each end along the long axis."""
    on = np.zeros(mesh.n_points, bool)
    on[faces_outer.ravel()] = True
    h = mesh.points @ frame.up
    top, bottom = h[on].max(), h[on].min()
    if 2 * length_mm >= top - bottom:
        raise UserError(f"clamps.length_mm = {length_mm:g} mm clamps the whole {top - bottom:.0f} mm bone")
    return Clamps(proximal=on & (h >= top - length_mm), distal=on & (h <= bottom + length_mm))


def _ray_triangle(origin, direction, tri):
    """Möller-Trumbore: distance along the ray to each triangle (inf where missed)."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = origin - tri[:, 0]
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ direction) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
    hit = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return np.where(hit, t, np.inf)


def section_centre(points: np.ndarray, faces: np.ndarray, frame: Frame, fraction: float) -> np.ndarray:
    """Centroid of the outer contour of the cross-section at ``fraction`` of the length from the
    proximal end (mean of the cut edges' midpoints, weighted by their length) [mm]."""
    level = frame.height(fraction)
    h = points @ frame.up - level
    tri = faces[np.ptp(np.sign(h[faces]), axis=1) > 0]
    mids, weights = [], []
    for t in tri:
        hv, xv = h[t], points[t]
        cut = [xv[i] + (xv[j] - xv[i]) * hv[i] / (hv[i] - hv[j])
               for i, j in ((0, 1), (1, 2), (2, 0)) if (hv[i] > 0) != (hv[j] > 0)]
        if len(cut) == 2:
            mids.append(0.5 * (cut[0] + cut[1]))
            weights.append(np.linalg.norm(cut[1] - cut[0]))
    if not mids:
        raise UserError(f"the bone has no cross-section at fraction {fraction:g} of its length")
    return np.average(np.array(mids), axis=0, weights=weights)


#: A drill enters the bone from the side: its direction must be at least this far from the long axis.
MIN_ANGLE_TO_AXIS_DEG = 30.0


def drill_side(frame: Frame, site) -> np.ndarray:
    """The unit direction across the long axis from which ``site.direction`` approaches the
    bone; refuses directions within :data:`MIN_ANGLE_TO_AXIS_DEG` of the axis (they would
    drill along the shaft, and a near-axial vector would otherwise pick an arbitrary side)."""
    d = frame.direction(site.direction)
    angle = np.degrees(np.arccos(min(1.0, abs(float(d @ frame.up)))))
    if angle < MIN_ANGLE_TO_AXIS_DEG:
        raise UserError(f"site.direction is {angle:.0f} degrees from the femur's long axis: the drill must enter "
                        f"from the side, at least {MIN_ANGLE_TO_AXIS_DEG:g} degrees from the axis")
    side = d - (d @ frame.up) * frame.up
    return side / np.linalg.norm(side)


def entry_point(tri: np.ndarray, frame: Frame, site, centre: np.ndarray) -> tuple[np.ndarray, int]:
    """Where a ray from outside, on the side named by ``site.direction``, towards ``centre``
    first meets the surface triangles ``tri`` (k, 3, 3); returns the point and the triangle."""
    side = drill_side(frame, site)
    start = centre + side * frame.length_mm
    t = _ray_triangle(start, -side, tri)
    if not np.isfinite(t).any():
        raise UserError(f"the drill direction at site '{site.name}' does not meet the bone surface")
    return start - side * t.min(), int(np.argmin(t))


def drill_site(mesh: TetMesh, frame: Frame, faces_outer: np.ndarray, site, centre,
               drill_radius_mm: float) -> DrillSite:
    """The drill site of ``site`` (the case's SiteSpec) on the mesh's outer surface; the
    normal is averaged over the drill's footprint (radius ``drill_radius_mm``)."""
    tri = mesh.points[faces_outer]
    entry, hit = entry_point(tri, frame, site, centre)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 × area
    near = np.linalg.norm(tri.mean(axis=1) - entry, axis=1) < drill_radius_mm
    near[hit] = True
    normal = normals[near].sum(axis=0)
    normal /= np.linalg.norm(normal)
    side = frame.direction(site.direction)
    direction = -(side - (side @ frame.up) * frame.up)
    direction /= np.linalg.norm(direction)
    return DrillSite(site.name, entry, normal, direction, round(cortical_depth(mesh, entry, direction), 3))


def cortical_depth(mesh: TetMesh, entry, direction, step_mm: float = 0.02, max_mm: float = 60.0) -> float:
    """Distance from ``entry`` along ``direction`` to where the ray first leaves cortical tets [mm]."""
    s = np.arange(step_mm / 2, max_mm, step_mm)
    cells = cells_along(mesh, entry, direction, s)
    cortical = (cells >= 0) & (mesh.region[np.maximum(cells, 0)] == CORTICAL)
    first = np.argmax(cortical)  # the entry lies on the surface: skip samples that round outside
    if not cortical[first]:
        return 0.0
    after = np.nonzero(~cortical[first:])[0]
    return float(s[first + after[0]] - step_mm / 2) if len(after) else float(max_mm)
