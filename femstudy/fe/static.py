"""Static equilibrium K_ff u_f = f_f on the free DOFs (u = 0 on the clamps).

The reduced matrices and the stiffness factorisation are cached on the system per
constraint set, so a static solve, the quasi-static reference of a transient and the modal
shift-invert all share one factorisation of K_ff.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from femstudy.fe import linsolve


def reduced(system, bc, name: str):
    """K_ff or M_ff (``name`` "K" or "M"), cached. Both use one reduced pattern (K and M share
    theirs), so ``K_ff.indices is M_ff.indices`` and K_ff + c M_ff is a sum of data arrays."""
    key = (bc.key, name)
    if key not in system.cache:
        indptr, indices, source = _free_pattern(system, bc)
        full = system.K if name == "K" else system.M
        system.cache[key] = sp.csr_matrix((full.data[source], indices, indptr), shape=(len(bc.free),) * 2)
    return system.cache[key]


def _free_pattern(system, bc):
    """The pattern of the free-DOF block of K and M, and the position in K.data / M.data of
    each of its entries (found once by restricting a matrix whose entries are their positions)."""
    key = (bc.key, "pattern")
    if key not in system.cache:
        K = system.K
        positions = sp.csr_matrix((np.arange(1, K.nnz + 1, dtype=float), K.indices, K.indptr), shape=K.shape)
        free = positions[bc.free][:, bc.free].tocsr()
        system.cache[key] = free.indptr, free.indices, free.data.astype(np.int64) - 1
    return system.cache[key]


def mass_product(system, bc):
    """x_f ↦ M_ff x_f [N per mm/s²] through the nodal mass (M = M_nodes ⊗ I₃): a ninth of
    M's entries to read, the product that dominates a transient step after the solve."""
    def product(x_free: np.ndarray) -> np.ndarray:  # x_free (n_free,) or (n_free, k)
        full = np.zeros((system.n_dofs,) + x_free.shape[1:])
        full[bc.free] = x_free
        nodal = full.reshape(system.M_nodes.shape[0], -1)  # a node's 3 (× k) values per row
        return (system.M_nodes @ nodal).reshape(full.shape)[bc.free]
    return product


def near_null_space(system, bc) -> np.ndarray:
    """Rigid-body modes restricted to the free DOFs (for AMG)."""
    return linsolve.rigid_body_modes(system.nodes)[bc.free]


def stiffness_factor(system, bc, method: str = "auto", console=None) -> linsolve.Factor:
    """The (cached) solver for K_ff."""
    key = (bc.key, "K-factor", method)
    if key not in system.cache:
        system.cache[key] = linsolve.factorize(reduced(system, bc, "K"), method,
                                               near_null_space(system, bc), console)
    return system.cache[key]


def solve_static(system, bc, f: np.ndarray, method: str = "auto", console=None) -> np.ndarray:
    """Displacements u [mm] (full DOF vector, or one column per load) for forces f [N]."""
    f = np.asarray(f, dtype=float)
    factor = stiffness_factor(system, bc, method, console)
    return bc.expand(factor.solve(f[bc.free]))
