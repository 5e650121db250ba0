"""The drill's load on the bone: unit thrust and unit torque patterns over the footprint.

The footprint is the part of the outer surface within the drill radius r of the drill axis,
facing the drill (outward normal · d < 0) and within r of the entry point along the axis
(which excludes the far cortex the axis also crosses). On a surface triangulation a disk
never coincides with whole facets, so the facets near the axis are integrated with a fine
composite rule (each facet split into s² sub-triangles of size ≤ r/10, one point each) and a
point counts when it lies inside the disk. With w_q the weights of the points inside,
A = Σ w_q the footprint area and c = Σ w_q x_q / A its centroid:

- thrust: uniform traction t = F d / A along the drill direction d (into the bone);
- torque: traction t = k d × (x − c) about the axis through c, k = T / Σ w_q ρ_q², with
  ρ the distance from that axis: tangential, growing linearly with radius, moment T d.

The nodal forces are f_i = Σ_q w_q N_i(x_q) t(x_q). Because the shape functions are a
partition of unity and reproduce x exactly (affine P1/P2 facets), Σ f_i = Σ_q w_q t_q and
Σ x_i × f_i = Σ_q w_q x_q × t_q: the discrete thrust is F d, the torque's net force is zero
and its moment about the axis is T, all to round-off (tests/test_fe_loads.py). Units: N,
N·mm, mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from femstudy.errors import UserError, require

#: Sub-triangle size as a fraction of the drill radius, and the cap on subdivisions per edge.
RESOLUTION = 0.1
MAX_SUBDIVISION = 64


@dataclass(frozen=True)
class DrillPatch:
    """Unit load patterns of the drill and the footprint average.

    thrust    : (n_dofs,) nodal forces [N] of a 1 N thrust along ``axis``
    torque    : (n_dofs,) nodal forces [N] of a 1 N·mm moment about the axis (vector ``axis``)
    mean      : (3, n_dofs) sparse; ``mean @ u`` is the footprint-averaged displacement [mm]
    centre    : (3,) footprint centroid [mm], on the torque axis
    area_mm2  : footprint area (compare π r²)
    facets    : boundary facets carrying load
    """

    thrust: np.ndarray
    torque: np.ndarray
    mean: sp.csr_matrix
    centre: np.ndarray
    axis: np.ndarray
    radius_mm: float
    area_mm2: float
    facets: np.ndarray
    n_points: int

    @property
    def patterns(self) -> np.ndarray:
        """(n_dofs, 2): columns thrust and torque, to pair with amplitudes (thrust_N, torque_Nmm)."""
        return np.column_stack([self.thrust, self.torque])

    def force(self, thrust_N: float, torque_Nmm: float) -> np.ndarray:
        return thrust_N * self.thrust + torque_Nmm * self.torque


def _subtriangle_centroids(s: int):
    """Centroids (barycentric ξ, η) of the s² congruent sub-triangles of the unit triangle."""
    i, j = np.meshgrid(np.arange(s), np.arange(s), indexing="ij")
    up = i + j <= s - 1
    down = i + j <= s - 2
    xi = np.concatenate([(i[up] + 1 / 3) / s, (i[down] + 2 / 3) / s])
    eta = np.concatenate([(j[up] + 1 / 3) / s, (j[down] + 2 / 3) / s])
    return xi, eta


def outward_facet_normals(mesh, facets: np.ndarray) -> np.ndarray:
    """Unit normals of boundary facets, pointing out of the mesh."""
    p = mesh.p.T
    tri = p[mesh.facets[:, facets].T]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    owner = mesh.t[:, mesh.f2t[0, facets]].T
    inside = p[owner].mean(axis=1)
    n *= np.where(np.einsum("ij,ij->i", n, tri[:, 0] - inside) < 0, -1.0, 1.0)[:, None]
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def facet_node_indices(system, facets: np.ndarray) -> np.ndarray:
    """(n, 3 or 6) node indices of the facets: vertices, then for P2 the mid-nodes of edges
    (v1, v2), (v0, v2), (v0, v1) — opposite vertex 0, 1, 2."""
    mesh = system.mesh
    v = mesh.facets[:, facets].T
    if system.order == 1:
        return v
    edges = np.sort(mesh.edges, axis=0)
    keys = edges[0].astype(np.int64) * mesh.nvertices + edges[1]
    order = np.argsort(keys)
    pairs = [np.sort(v[:, [1, 2]], axis=1), np.sort(v[:, [0, 2]], axis=1), np.sort(v[:, [0, 1]], axis=1)]
    mids = [order[np.searchsorted(keys[order], a.astype(np.int64) * mesh.nvertices + b)] for a, b in
            (pair.T for pair in pairs)]
    return np.column_stack([v] + [mesh.nvertices + m for m in mids])


def trace_shape_functions(order: int, lam: np.ndarray) -> np.ndarray:
    """Facet shape functions at barycentric points lam (..., 3), node order of facet_node_indices."""
    if order == 1:
        return lam
    l0, l1, l2 = lam[..., 0], lam[..., 1], lam[..., 2]
    return np.stack([l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1),
                     4 * l1 * l2, 4 * l0 * l2, 4 * l0 * l1], axis=-1)


def drill_patch(system, site, radius_mm: float) -> DrillPatch:
    """Unit thrust and torque load patterns over the drill footprint at ``site``
    (:class:`femstudy.femur_mesh.DrillSite`) for a drill of radius ``radius_mm``."""
    require(radius_mm > 0, f"drill radius must be positive, got {radius_mm} mm")
    mesh = system.mesh
    d = np.asarray(site.direction, float)
    d = d / np.linalg.norm(d)
    e = np.asarray(site.entry_point, float)

    boundary = mesh.boundary_facets()
    tri = mesh.p.T[mesh.facets[:, boundary].T]
    size = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    rel = tri - e
    axial = rel @ d
    radial = np.linalg.norm(rel - axial[..., None] * d, axis=2)
    near = ((radial.min(axis=1) <= radius_mm + size) & (np.abs(axial).min(axis=1) <= radius_mm + size))
    candidates = boundary[near]
    if len(candidates):
        candidates = candidates[outward_facet_normals(mesh, candidates) @ d < 0]
    missed = UserError(f"the drill footprint (radius {radius_mm} mm) at {np.round(e, 2).tolist()} touches no mesh "
                       "surface facing the drill; is the site on this mesh's outer surface, drilling inwards?")
    if len(candidates) == 0:
        raise missed

    corners = mesh.p.T[mesh.facets[:, candidates].T]
    edge_len = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max()
    s = int(min(MAX_SUBDIVISION, max(1, np.ceil(edge_len / (RESOLUTION * radius_mm)))))
    xi, eta = _subtriangle_centroids(s)
    lam = np.column_stack([1 - xi - eta, xi, eta])
    x = np.einsum("qk,fkj->fqj", lam, corners)
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    w = np.repeat(area[:, None] / s ** 2, len(xi), axis=1)
    rel = x - e
    axial = rel @ d
    radial = np.linalg.norm(rel - axial[..., None] * d, axis=2)
    w = np.where((radial <= radius_mm) & (np.abs(axial) <= radius_mm), w, 0.0)
    if not w.any():
        raise missed
    used = w.any(axis=1)
    facets, x, w = candidates[used], x[used], w[used]
    nodes = facet_node_indices(system, facets)
    N = trace_shape_functions(system.order, lam)

    A = w.sum()
    c = np.einsum("fq,fqj->j", w, x) / A
    r_vec = x - c
    r_vec -= (r_vec @ d)[..., None] * d
    k = 1.0 / np.einsum("fq,fq->", w, np.einsum("fqj,fqj->fq", r_vec, r_vec))
    traction_thrust = np.broadcast_to(d / A, x.shape)
    traction_torque = k * np.cross(d, x - c)

    def nodal(traction):
        load = np.einsum("fq,qa,fqj->faj", w, N, traction)
        return np.bincount((3 * nodes[..., None] + np.arange(3)).ravel(), load.ravel(), minlength=system.n_dofs)

    weights = np.einsum("fq,qa->fa", w, N) / A
    cols = (3 * nodes[..., None] + np.arange(3)).reshape(-1)
    rows = np.tile(np.arange(3), nodes.size)
    mean = sp.csr_matrix((np.repeat(weights.ravel(), 3), (rows, cols)), shape=(3, system.n_dofs))
    return DrillPatch(nodal(traction_thrust), nodal(traction_torque), mean, c, d, float(radius_mm), float(A),
                      facets, int(np.count_nonzero(w)))
