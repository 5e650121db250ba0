"""Static equilibrium K_ff u_f = f_f on the free DOFs (u = 0 on the clamps).

The reduced matrices and the stiffness factorisation are cached on the system per
constraint set, so a static solve, the quasi-static reference of a transient and the modal
shift-invert all share one factorisation of K_ff.
"""

from __future__ import annotations

import numpy as np

from femstudy.fe import linsolve


def reduced(system, bc, name: str):
    """K_ff or M_ff (``name`` "K" or "M"), cached."""
    key = (bc.key, name)
    if key not in system.cache:
        full = system.K if name == "K" else system.M
        system.cache[key] = full[bc.free][:, bc.free].tocsr()
    return system.cache[key]


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
