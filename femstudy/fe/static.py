"""The clamped model factorised once: K_ff u_f = f_f on the free DOFs (u = 0 on the clamps).

:func:`factorize` factorises K_ff, K restricted to the free DOFs; the static solve, the modal
analysis (shift-invert about 0 is K_ff⁻¹) and the transient's reduced basis
(femstudy.fe.transient) all use that one factorisation. K_ff and M_ff are formed when an
analysis needs their entries (PARDISO takes K's blocks restricted as they are).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property, partial
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from femstudy.fe import linsolve, sparse_products
from femstudy.fe.assembly import FESystem
from femstudy.fe.constraints import Constraints
from femstudy.fe.kept import KeptSolutions
from femstudy.fe.linsolve import free_block

__all__ = ["FactorizedSystem", "factorize", "free_block", "free_nodes", "solve_static"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class FactorizedSystem:
    """An assembled model under one set of clamps, with K_ff factorised.

    system    : the assembled :class:`~femstudy.fe.assembly.FESystem`
    bc        : the clamps (:class:`~femstudy.fe.constraints.Constraints`)
    factor    : the solver of K_ff (:class:`femstudy.fe.linsolve.Factor`)
    formed    : K_ff's entries when they were formed to be factorised or to be found among kept
                solutions; else (a static solve with clamps holding whole nodes factorises a
                :class:`~femstudy.fe.linsolve.Restriction`) they are formed when first asked for
    stiffness : K_ff [N/mm]: BSR of 3×3 node blocks when the clamps hold whole nodes, else CSR
    K, M      : K_ff [N/mm] and M_ff [tonne], CSR on one shared pattern, so K + c M is a sum of
                their data arrays; each is formed when first asked for (a static solve, the
                modal analysis and a reduced transient from rest need neither: their products
                go through :meth:`stiffness_times` and :meth:`mass`)
    """

    system: FESystem
    bc: Constraints
    factor: linsolve.Factor
    formed: sp.csr_matrix | sp.bsr_matrix | None = None

    @cached_property
    def stiffness(self) -> sp.csr_matrix | sp.bsr_matrix:
        if self.formed is not None:
            return self.formed
        nodes = free_nodes(self.bc)
        return free_block(self.system.K, self.bc.free) if nodes is None else free_block(self.system.K_blocks, nodes)

    @cached_property
    def K(self) -> sp.csr_matrix:
        return self.stiffness.tocsr() if self.stiffness.format == "bsr" else self.stiffness

    @cached_property
    def M(self) -> sp.csr_matrix:
        return free_block(self.system.M, self.bc.free)

    @property
    def n_free(self) -> int:
        return len(self.bc.free)

    @property
    def method(self) -> str:
        """The linear solver that factorised K_ff (pardiso, cholmod, superlu or amg)."""
        return self.factor.method

    def solve(self, f: np.ndarray) -> np.ndarray:
        """Displacements u [mm] (full DOF vector, or one column per load) for forces f [N]."""
        f = np.asarray(f, dtype=float)
        return self.bc.expand(self.factor.solve(f[self.bc.free]))

    def stiffness_times(self, x_free: np.ndarray) -> np.ndarray:
        """K_ff x [N] for x (n_free,) or (n_free, k) [mm], as K's assembled blocks times x
        padded with zeros on the clamps: K_ff itself is not formed (at 16 mm forming its CSR
        copy costs 0.3 s, about a tenth of a whole static process)."""
        return linsolve.restricted_product(self.system.K_blocks, self.bc.free, x_free)

    def mass(self, x_free: np.ndarray) -> np.ndarray:
        """M_ff x [N per mm/s²] for x (n_free,) or (n_free, k), through the nodal mass
        (M = M_nodes ⊗ I₃: a ninth of M's entries to read)."""
        full = linsolve.padded(x_free, self.bc.free, self.system.n_dofs)
        nodal = full.reshape(self.system.M_nodes.shape[0], -1)  # a node's 3 (× k) values per row
        return sparse_products.times(self.system.M_nodes, nodal).reshape(full.shape)[self.bc.free]

    def near_null_space(self) -> np.ndarray:
        """Rigid-body modes restricted to the free DOFs (for AMG)."""
        return linsolve.rigid_body_modes(self.system.nodes)[self.bc.free]


def free_nodes(bc: Constraints) -> np.ndarray | None:
    """The nodes whose three DOFs are all free, when the clamps hold whole nodes (every DOF of
    a node fixed or none); None otherwise."""
    if len(bc.free) % 3:
        return None
    nodes = bc.free[::3] // 3
    return nodes if np.array_equal(bc.free, (3 * nodes[:, None] + np.arange(3)).ravel()) else None


def factorize(system: FESystem, bc: Constraints, solver: str = "auto", keep: Path | None = None,
              precision: str = "double") -> FactorizedSystem:
    """Restrict the model to the free DOFs of ``bc`` and factorise K_ff.

    Parameters
    ----------
    system : FESystem
        From :func:`femstudy.fe.assemble`.
    bc : Constraints
        From :func:`femstudy.fe.clamp` or :func:`femstudy.fe.fix_facets`.
    solver : str
        "auto" or one of :data:`femstudy.fe.linsolve.METHODS`.
    keep : Path, optional
        Folder of kept solutions (:mod:`femstudy.fe.kept`): K_ff is then factorised only when
        a solve is not served by the solutions an earlier run kept for the same K_ff, and
        :meth:`~femstudy.fe.linsolve.Factor.close` stores the new ones.
    precision : str
        PARDISO's factorisation: "double" (one substitution per solve: the choice for the
        many solves of a transient, modal analysis or study) or "single" (half the memory and
        about half the time, each solve refined to double precision in 5–6 substitutions: the
        faster choice for a static analysis's one or two solves).

    Returns
    -------
    FactorizedSystem

    Examples
    --------
    >>> fs = factorize(system, bc)                      # doctest: +SKIP
    >>> u = solve_static(fs, patch.force(30.0, 40.0))   # doctest: +SKIP
    """
    # clamps that hold whole nodes: PARDISO takes the assembled blocks restricted as they are
    nodes = free_nodes(bc)

    def make(A) -> linsolve.Factor:
        return linsolve.factorize(A, solver, linsolve.rigid_body_modes(system.nodes)[bc.free], precision)

    if keep is None:
        if nodes is not None:
            restriction = linsolve.Restriction(system.K_blocks, nodes)
            factor = make(restriction)   # the solvers other than PARDISO form K_ff: kept then
            return FactorizedSystem(system, bc, factor, restriction.formed)
        K = free_block(system.K, bc.free)
        return FactorizedSystem(system, bc, make(K), K)
    # kept solutions are found by K_ff's entries: its node blocks when the clamps hold whole nodes
    entries = free_block(system.K, bc.free) if nodes is None else free_block(system.K_blocks, nodes)
    return FactorizedSystem(system, bc, KeptSolutions(entries, partial(make, entries), keep), entries)


def solve_static(fs: FactorizedSystem, f: np.ndarray) -> np.ndarray:
    """Static displacements u [mm] (full DOF vector, or one column per load) under forces f [N].

    Parameters
    ----------
    fs : FactorizedSystem
    f : ndarray, (n_dofs,) or (n_dofs, k)

    Returns
    -------
    ndarray
        Same shape as ``f``; zero on the clamped DOFs.
    """
    return fs.solve(f)
