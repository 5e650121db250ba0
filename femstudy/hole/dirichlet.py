"""Static solves with prescribed (non-zero) displacements, the boundary condition of a submodel.

With the DOFs split into free (f) and prescribed (p) sets, K_ff u_f = f_f − K_fp u_p and
u_p = ū. :func:`factorize_prescribed` factorises K_ff once per prescribed set
(:func:`femstudy.fe.static.factorize`) and keeps K_fp, so every load pattern and every
prescribed field of one station costs a forward/backward substitution. Units: mm, N.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from femstudy.errors import require
from femstudy.fe.constraints import Constraints
from femstudy.fe.loads import facet_node_indices
from femstudy.fe.static import FactorizedSystem, factorize


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

    Examples
    --------
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
    return np.unique(facet_node_indices(system, np.asarray(facets)))


def node_dofs(nodes: np.ndarray, components=(0, 1, 2)) -> np.ndarray:
    """(n, len(components)) DOF numbers of the nodes' chosen displacement components."""
    return 3 * np.asarray(nodes)[:, None] + np.asarray(components)[None, :]


@dataclass(frozen=True, eq=False)
class PrescribedSystem:
    """A model with a set of DOFs prescribed, K_ff factorised once.

    fs   : the :class:`~femstudy.fe.static.FactorizedSystem` (``fs.bc.fixed`` the prescribed DOFs, sorted)
    K_fp : the coupling block K[free, fixed] [N/mm]
    """

    fs: FactorizedSystem
    K_fp: sp.csr_matrix

    @property
    def dofs(self) -> np.ndarray:
        """The prescribed DOFs, sorted (the row order of ``values`` in :meth:`solve`)."""
        return self.fs.bc.fixed

    def solve(self, values: np.ndarray, forces: np.ndarray | None = None) -> np.ndarray:
        """Displacements u [mm] with u[dofs] = values (rows in :attr:`dofs` order) and nodal
        ``forces`` [N] elsewhere; values (m,) or (m, k), forces (n_dofs,) or (n_dofs, k)."""
        system, bc = self.fs.system, self.fs.bc
        values = np.asarray(values, float)
        require(values.shape[0] == len(bc.fixed), f"{values.shape[0]} prescribed values for {len(bc.fixed)} DOFs")
        columns = values.shape[1:]
        forces = np.zeros((system.n_dofs,) + columns) if forces is None else np.asarray(forces, float)
        require(forces.shape[0] == system.n_dofs, f"forces have {forces.shape[0]} rows for {system.n_dofs} DOFs")
        if forces.ndim > values.ndim:
            values = np.repeat(values[:, None], forces.shape[1], axis=1)
        elif values.ndim > forces.ndim:
            forces = np.repeat(forces[:, None], values.shape[1], axis=1)
        u = np.zeros_like(forces)
        u[bc.fixed] = values
        u[bc.free] = self.fs.factor.solve(forces[bc.free] - self.K_fp @ values)
        return u


def factorize_prescribed(system, dofs: np.ndarray, solver: str = "auto", keep: Path | None = None) -> PrescribedSystem:
    """Factorise K_ff with ``dofs`` prescribed (the submodel's cut boundary).

    Parameters
    ----------
    system : :class:`femstudy.fe.FESystem`
    dofs : (m,) distinct DOF numbers to prescribe (enough to remove rigid-body motion)
    solver : "auto" or a linear solver of :data:`femstudy.fe.linsolve.METHODS`
    keep : folder of kept solutions (:func:`femstudy.fe.static.factorize`), optional

    Returns
    -------
    PrescribedSystem

    Examples
    --------
    >>> ps = factorize_prescribed(system, cut_dofs)                # doctest: +SKIP
    >>> u = ps.solve(exact(system.nodes).ravel()[ps.dofs], loads)  # doctest: +SKIP
    """
    dofs = np.asarray(dofs, dtype=np.int64).ravel()
    fixed = np.sort(dofs)
    require(len(np.unique(fixed)) == len(fixed), "a DOF is prescribed twice")
    free = np.setdiff1d(np.arange(system.n_dofs), fixed)
    fs = factorize(system, Constraints(fixed, free, np.empty(0, np.int64)), solver, keep)
    return PrescribedSystem(fs, system.K[free][:, fixed].tocsr())


def solve_prescribed(system, dofs: np.ndarray, values: np.ndarray, forces: np.ndarray | None = None,
                     solver: str = "auto") -> np.ndarray:
    """One solve with prescribed displacements: :func:`factorize_prescribed` then
    :meth:`PrescribedSystem.solve` (factorise once and reuse it for several solves).

    Parameters
    ----------
    system : :class:`femstudy.fe.FESystem`
    dofs : (m,) distinct DOF numbers to prescribe
    values : (m,) or (m, k) their displacements [mm], in the order of ``dofs``
    forces : (n_dofs,) or (n_dofs, k) nodal forces [N]; default none
    solver : linear solver (:func:`femstudy.fe.linsolve.factorize`)

    Returns
    -------
    (n_dofs,) or (n_dofs, k) displacement vector(s) [mm]

    Examples
    --------
    >>> u = solve_prescribed(system, dofs, exact(system.nodes).ravel()[dofs])  # doctest: +SKIP
    """
    dofs = np.asarray(dofs, dtype=np.int64).ravel()
    values = np.asarray(values, float)
    require(values.shape[0] == len(dofs), f"{values.shape[0]} prescribed values for {len(dofs)} DOFs")
    return factorize_prescribed(system, dofs, solver).solve(values[np.argsort(dofs)], forces)
