"""Unit responses of samples that change the stiffness: a reduced basis with a bounded error.

The moduli enter K linearly: K(θ) = θ_c K_c + θ_s K_s, K_c and K_s the cortical and cancellous
parts of the case's K (θ the modulus factors); the clamped length L changes the fixed DOFs S(L)
(outer-surface nodes within L of each end). A sample's unit responses u_j (K(θ) u_j = p_j on
the free DOFs, u_j = 0 on S(L), p_j the unit thrust and torque patterns) are sought in
span V ∩ {v : v_S = 0} by Galerkin projection, V the orthonormalised responses at a few
*snapshot* parameters (:func:`train`). Their residual r_j = (K(θ) u_j − p_j) on the free DOFs
bounds the error of every DOF:

    ‖u_j − u_j,exact‖₂ ≤ ‖r_j‖₂ / λ_min(K_ff(θ, L)),   λ_min(K_ff(θ, L)) ≥ min(θ_c, θ_s) λ₀,

λ₀ the smallest eigenvalue of K_ff at θ = 1 and the shortest clamped length of the design: K(θ)
− min θ · K(1) is a sum of positive semi-definite parts, and a longer clamp's K_ff is a
principal submatrix of the shorter one's (Cauchy interlacing). A sample whose bound exceeds
``rtol`` of its largest unit displacement is solved directly instead (a factorisation; counted).
The snapshots are chosen greedily on the design's own stiffness points, worst bound first, so a
design that passes its training needs no direct solve. Units: mm, N, N·mm, MPa.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from femstudy import fe
from femstudy.materials import BoneMaterials
from femstudy.meshing.landmarks import clamps as clamp_masks, outer_faces

log = logging.getLogger(__name__)

#: Largest error bound accepted, relative to the largest unit displacement of the sample.
RTOL = 1e-3
#: Most snapshot parameters of a basis (each adds the two unit responses).
MAX_SNAPSHOTS = 30
#: Singular values of V restricted to the fixed DOFs below this (relative) count as zero.
NULL_TOL = 1e-9


@dataclass(frozen=True)
class StiffnessPoint:
    """The stiffness inputs of a sample: modulus factors and clamped length [mm]."""

    cortical: float = 1.0
    cancellous: float = 1.0
    clamp_length_mm: float = 20.0

    @classmethod
    def of(cls, values: dict, clamp_length_mm: float) -> "StiffnessPoint":
        return cls(float(values.get("cortical_modulus_factor", 1.0)), float(values.get("cancellous_modulus_factor", 1.0)),
                   float(values.get("clamp_length_mm", clamp_length_mm)))


@dataclass
class StiffnessFamily:
    """K(θ) = θ_c K_c + θ_s K_s and the clamp sets of a femur's model (full DOFs)."""

    system: fe.FESystem
    femur: object
    patterns: np.ndarray
    K_c: sp.csr_matrix
    K_s: sp.csr_matrix
    _outer: np.ndarray = field(repr=False)
    _sets: dict = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, model) -> "StiffnessFamily":
        """From a :class:`femstudy.GlobalModel`: K_s = K(cancellous × 2) − K, K_c = K − K_s
        (one more assembly)."""
        mats = model.case.materials.to_fe()
        doubled = BoneMaterials(mats.cortical, replace(mats.cancellous, E_MPa=2 * mats.cancellous.E_MPa),
                                mats.cortical_model)
        other = fe.assemble(model.femur.mesh, doubled, order=model.system.order, long_axis=model.femur.frame.up)
        K_s = (other.K - model.system.K).tocsr()
        K_c = (model.system.K - K_s).tocsr()
        return cls(model.system, model.femur, np.asarray(model.patch.patterns), K_c, K_s,
                   outer_faces(model.femur.mesh, model.femur.frame))

    def K(self, p: StiffnessPoint) -> sp.csr_matrix:
        return (p.cortical * self.K_c + p.cancellous * self.K_s).tocsr()

    def constraints(self, clamp_length_mm: float) -> fe.Constraints:
        """The fixed DOFs of a clamped length (cached by the clamped node sets)."""
        masks = clamp_masks(self.femur.mesh, self.femur.frame, self._outer, clamp_length_mm)
        key = (int(masks.proximal.sum()), int(masks.distal.sum()))
        if key not in self._sets:
            self._sets[key] = fe.clamp(self.system, masks)
        return self._sets[key]

    def solve(self, p: StiffnessPoint, solver: str = "auto") -> np.ndarray:
        """(n_dofs, 2) unit responses at ``p`` by a factorisation."""
        bc = self.constraints(p.clamp_length_mm)
        fs = fe.factorize(replace(self.system, K=self.K(p)), bc, solver)
        try:
            return bc.expand(fs.factor.solve(self.patterns[bc.free]))
        finally:
            fs.factor.close()

    def smallest_eigenvalue(self, clamp_length_mm: float, solver: str = "auto") -> float:
        """λ_min of K_ff at θ = 1 and ``clamp_length_mm`` [N/mm] (Lanczos on K_ff⁻¹)."""
        bc = self.constraints(clamp_length_mm)
        fs = fe.factorize(replace(self.system, K=self.K(StiffnessPoint())), bc, solver)
        try:
            n = len(bc.free)
            op = sla.LinearOperator((n, n), matvec=lambda x: fs.factor.solve(np.asarray(x, float).ravel()), dtype=float)
            largest = sla.eigsh(op, k=1, which="LA", tol=1e-6, return_eigenvectors=False)[0]
        finally:
            fs.factor.close()
        return float(1.0 / largest)


@dataclass
class ReducedBasis:
    """An orthonormal basis V of snapshot responses with its projections (see the module docstring).

    V : (n_dofs, r); snapshots : the parameters solved; eigenvalue : λ₀ [N/mm]
    """

    family: StiffnessFamily
    V: np.ndarray
    snapshots: list
    eigenvalue: float
    _G: tuple = field(default=None, repr=False)
    _nulls: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        self._project()

    def _project(self) -> None:
        KcV, KsV = self.family.K_c @ self.V, self.family.K_s @ self.V
        self._G = (KcV, KsV, self.V.T @ KcV, self.V.T @ KsV, self.V.T @ self.family.patterns)
        self._nulls = {}

    def add(self, p: StiffnessPoint, fields: np.ndarray) -> None:
        """Add a snapshot's responses (orthonormalised against V)."""
        X = fields - self.V @ (self.V.T @ fields)
        X = X - self.V @ (self.V.T @ X)
        Q, R = np.linalg.qr(X)
        keep = np.abs(np.diag(R)) > 1e-12 * np.linalg.norm(fields, axis=0).max()
        self.V = np.hstack([self.V, Q[:, keep]])
        self.snapshots.append(p)
        self._project()

    def _null(self, bc: fe.Constraints) -> np.ndarray:
        key = bc.key
        if key not in self._nulls:
            _, s, Vt = np.linalg.svd(self.V[bc.fixed], full_matrices=True)
            rank = int(np.sum(s > NULL_TOL * max(s.max(initial=0.0), 1.0)))
            self._nulls[key] = Vt[rank:].T
        return self._nulls[key]

    def evaluate(self, p: StiffnessPoint) -> tuple[np.ndarray, np.ndarray]:
        """(n_dofs, 2) unit responses at ``p`` and the bound on each column's error [mm]."""
        KcV, KsV, Gc, Gs, VP = self._G
        bc = self.family.constraints(p.clamp_length_mm)
        N = self._null(bc)
        A = N.T @ (p.cortical * Gc + p.cancellous * Gs) @ N
        y = N @ np.linalg.solve(A, N.T @ VP)
        residual = (p.cortical * KcV + p.cancellous * KsV) @ y - self.family.patterns
        r = np.linalg.norm(residual[bc.free], axis=0)
        return self.V @ y, r / (min(p.cortical, p.cancellous) * self.eigenvalue)


def relative_bound(fields: np.ndarray, bound: np.ndarray) -> float:
    """The larger column's bound over its largest nodal displacement."""
    peak = np.linalg.norm(fields.reshape(-1, 3, fields.shape[1]), axis=1).max(axis=0)
    return float(np.max(bound / np.maximum(peak, 1e-300)))


def train(family: StiffnessFamily, nominal: StiffnessPoint, nominal_fields: np.ndarray, points: list,
          solver: str = "auto", rtol: float = RTOL, max_snapshots: int = MAX_SNAPSHOTS) -> ReducedBasis:
    """A basis whose bound is below ``rtol`` at every training point: the nominal responses
    (``nominal_fields``, the study's static shapes), then greedily the worst training point."""
    shortest = min([p.clamp_length_mm for p in points] + [nominal.clamp_length_mm])
    eigenvalue = family.smallest_eigenvalue(shortest, solver)
    log.info("reduced basis: lambda_min(K_ff) = %.4g N/mm at clamp length %.3g mm", eigenvalue, shortest)
    basis = ReducedBasis(family, np.zeros((nominal_fields.shape[0], 0)), [], eigenvalue)
    basis.add(nominal, nominal_fields)
    while len(basis.snapshots) < max_snapshots:
        worst, where = 0.0, None
        for p in points:
            fields, bound = basis.evaluate(p)
            rel = relative_bound(fields, bound)
            if rel > worst:
                worst, where = rel, p
        log.info("reduced basis: %d snapshots, largest relative bound %.3g", len(basis.snapshots), worst)
        if worst <= rtol or where is None:
            break
        basis.add(where, family.solve(where, solver))
    return basis
