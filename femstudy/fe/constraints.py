"""Clamped (fixed) boundary: which DOFs are held at zero displacement.

A boundary facet is clamped when all three of its vertices are clamped points; every DOF
on it (its vertices' and, for P2, its edge mid-nodes') is fixed. The solver works on the
remaining free DOFs: K_ff u_f = f_f.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from femstudy.errors import UserError, require


@dataclass(frozen=True)
class Constraints:
    """fixed, free : sorted DOF indices; facets : the clamped boundary facets (mesh indices)."""

    fixed: np.ndarray
    free: np.ndarray
    facets: np.ndarray

    @property
    def key(self) -> str:
        """A short fingerprint of the fixed set, for caching factorisations."""
        return hashlib.sha1(self.fixed.tobytes()).hexdigest()[:16]

    def expand(self, u_free: np.ndarray) -> np.ndarray:
        """The full DOF vector(s) with zeros at the fixed DOFs."""
        u = np.zeros((len(self.fixed) + len(self.free),) + u_free.shape[1:])
        u[self.free] = u_free
        return u


def fix_facets(system, facets: np.ndarray) -> Constraints:
    """Fix every DOF of the given boundary facets; refuse a set that leaves rigid-body motion."""
    facets = np.asarray(facets, dtype=np.int64)
    if len(facets) == 0:
        raise UserError("the clamps select no boundary facet: every facet needs all three vertices "
                        "clamped; enlarge the clamped length or check the clamp masks")
    fixed = np.unique(system.dofs.get_facet_dofs(facets).flatten())
    # one fully fixed facet (three non-collinear points) removes a piece's six rigid-body
    # modes, so only pieces of the mesh without any clamped facet can still move freely
    _require_every_part_clamped(system, np.unique(system.mesh.facets[:, facets]))
    free = np.setdiff1d(np.arange(system.n_dofs), fixed)
    return Constraints(fixed, free, facets)


def _require_every_part_clamped(system, clamped_vertices: np.ndarray) -> None:
    """Every connected piece of the mesh must touch a clamp, or it floats freely."""
    t = system.mesh.t
    n = system.mesh.nvertices
    graph = sp.coo_matrix((np.ones(3 * t.shape[1]), (np.repeat(t[0], 3), t[1:].T.ravel())), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    floating = np.setdiff1d(np.arange(count), label[clamped_vertices])
    if len(floating):
        cells = np.isin(label[t[0]], floating).sum()
        raise UserError(f"{len(floating)} of the mesh's {count} disconnected pieces ({cells} tetrahedra) "
                        "touch no clamp and would move as rigid bodies; remove them or clamp them")


def clamp(system, clamps) -> Constraints:
    """Constraints from :class:`femstudy.femur_mesh.Clamps` masks over the input mesh points."""
    mask = np.zeros(system.mesh.nvertices, dtype=bool)
    for part in (clamps.proximal, clamps.distal):
        part = np.asarray(part, dtype=bool)
        require(part.shape == system.point_index.shape,
                f"a clamp mask has {part.size} entries but the mesh has {system.point_index.size} points")
        index = system.point_index[part]
        mask[index[index >= 0]] = True
    boundary = system.mesh.boundary_facets()
    facets = boundary[mask[system.mesh.facets[:, boundary]].all(axis=0)]
    return fix_facets(system, facets)
