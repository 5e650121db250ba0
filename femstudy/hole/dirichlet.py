"""Static solves with prescribed (non-zero) displacements, the boundary condition of a submodel.

With the DOFs split into free (f) and prescribed (p) sets, K_ff u_f = f_f − K_fp u_p and
u_p = ū. K_ff is factorised once per prescribed set (cached on the system by
:func:`femstudy.fe.static.stiffness_factor`), so every load pattern and every prescribed field
of one station costs a forward/backward substitution. Units: mm, N.
"""

from __future__ import annotations

import numpy as np

from femstudy.errors import require
from femstudy.fe.constraints import Constraints
from femstudy.fe.loads import _facet_nodes
from femstudy.fe.static import stiffness_factor


def facet_indices(system, faces: np.ndarray) -> np.ndarray:
    """scikit-fem facet indices of ``faces`` (k, 3), given as point indices of the TetMesh the
    system was assembled from.

    Parameters
    ----------
    system : :class:`femstudy.fe.FESystem`
    faces : (k, 3) point indices

    Returns
    -------
    (k,) indices into ``system.mesh.facets``

    Example
    -------
    >>> facet_indices(system, station.faces["hole_wall"])  # doctest: +SKIP
    """
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    vertices = system.point_index[faces]
    require(np.all(vertices >= 0), "some faces use points that are not in the assembled mesh")
    n = np.int64(system.mesh.nvertices)
    mesh_facets = np.sort(system.mesh.facets.T, axis=1).astype(np.int64)
    keys = (mesh_facets[:, 0] * n + mesh_facets[:, 1]) * n + mesh_facets[:, 2]
    wanted = np.sort(vertices, axis=1)
    query = (wanted[:, 0] * n + wanted[:, 1]) * n + wanted[:, 2]
    order = np.argsort(keys)
    position = np.searchsorted(keys[order], query)
    found = (position < len(keys)) & (keys[order][np.minimum(position, len(keys) - 1)] == query)
    require(found.all(), f"{np.sum(~found)} faces are not facets of the assembled mesh")
    return order[position]


def facet_nodes(system, facets: np.ndarray) -> np.ndarray:
    """Sorted node indices (vertices and, for P2, edge mid-nodes) on the given facets."""
    return np.unique(_facet_nodes(system, np.asarray(facets)))


def node_dofs(nodes: np.ndarray, components=(0, 1, 2)) -> np.ndarray:
    """(n, len(components)) DOF numbers of the nodes' chosen displacement components."""
    return 3 * np.asarray(nodes)[:, None] + np.asarray(components)[None, :]


def solve_prescribed(system, dofs: np.ndarray, values: np.ndarray, forces: np.ndarray | None = None,
                     method: str = "auto") -> np.ndarray:
    """Displacements u [mm] with u[dofs] = values and nodal ``forces`` [N] on the other DOFs.

    Parameters
    ----------
    system : :class:`femstudy.fe.FESystem`
    dofs : (m,) distinct DOF numbers to prescribe (enough to remove rigid-body motion)
    values : (m,) or (m, k) their displacements [mm]
    forces : (n_dofs,) or (n_dofs, k) nodal forces [N]; default none
    method : linear solver (:func:`femstudy.fe.linsolve.factorize`)

    Returns
    -------
    (n_dofs,) or (n_dofs, k) displacement vector(s) [mm]

    Example
    -------
    >>> u = solve_prescribed(system, dofs, exact(system.nodes).ravel()[dofs])  # doctest: +SKIP
    """
    dofs = np.asarray(dofs, dtype=np.int64).ravel()
    order = np.argsort(dofs)
    fixed = dofs[order]
    require(len(np.unique(fixed)) == len(fixed), "a DOF is prescribed twice")
    values = np.asarray(values, float)
    require(values.shape[0] == len(dofs), f"{values.shape[0]} prescribed values for {len(dofs)} DOFs")
    values = values[order]
    columns = values.shape[1:]
    forces = np.zeros((system.n_dofs,) + columns) if forces is None else np.asarray(forces, float)
    require(forces.shape[0] == system.n_dofs, f"forces have {forces.shape[0]} rows for {system.n_dofs} DOFs")
    if forces.ndim > values.ndim:
        values = np.repeat(values[:, None], forces.shape[1], axis=1)
    elif values.ndim > forces.ndim:
        forces = np.repeat(forces[:, None], values.shape[1], axis=1)
    free = np.setdiff1d(np.arange(system.n_dofs), fixed)
    bc = Constraints(fixed, free, np.empty(0, np.int64))
    key = (bc.key, "K_fp")
    if key not in system.cache:
        system.cache[key] = system.K[free][:, fixed].tocsr()
    u = np.zeros_like(forces)
    u[fixed] = values
    u[free] = stiffness_factor(system, bc, method).solve(forces[free] - system.cache[key] @ values)
    return u
