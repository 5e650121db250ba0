"""Unit responses of samples that change the stiffness: reduced bases with a bounded error.

The moduli enter K linearly: K(θ) = θ_c K_c + θ_s K_s, K_c and K_s the cortical and cancellous
parts of the case's K (θ the modulus factors). The clamped length changes which DOFs are fixed
(outer-surface nodes within L of each end); each distinct clamped set gets its own basis.

For one clamped set, with A = K_ff(1) factorised once, a sample's unit responses u_j
(K_ff(θ) u_j = p_j, p_j the unit thrust and torque patterns) are the Galerkin solutions in
span V, V the orthonormalised responses at a few snapshot moduli (the first is θ = 1, A's own).
Their residual r_j = K_ff(θ) u_j − p_j lies in span W = [K_c V, K_s V, P], so its dual norm is a
small quadratic form, G = Wᵀ A⁻¹ W being computed once, and it bounds the error in energy:

    ‖u_j − u_j,exact‖_K(θ) = ‖r_j‖_K(θ)⁻¹ ≤ ‖r_j‖_A⁻¹ / √min(θ_c, θ_s)

(K(θ) − min θ · K(1) is a sum of positive semi-definite parts, so K(θ)⁻¹ ⪯ A⁻¹ / min θ). A
linear output ℓ(u) is then bounded by |ℓ(e)| ≤ ‖ℓ‖_A⁻¹ ‖e‖_K / √min θ: the drill point's
displacement D u gets |D e| ≤ √(λ_max(D A⁻¹ Dᵀ) / min θ) ‖e‖_K. Snapshots are added greedily
at the design's worst moduli of that set until the energy error is below :data:`RTOL` of the
response's energy norm everywhere on it; a sample that still fails is solved directly (a
factorisation; counted). Units: mm, N, N·mm.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from femstudy import fe
from femstudy.materials import BoneMaterials
from femstudy.meshing.landmarks import clamps as clamp_masks, outer_faces

if TYPE_CHECKING:
    from femstudy.meshing.model import FemurModel

log = logging.getLogger(__name__)

#: Largest energy-norm error accepted, relative to the response's energy norm.
RTOL = 1e-3
#: Most snapshot moduli of one clamped set's basis.
MAX_SNAPSHOTS = 12


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
    """K(θ) = θ_c K_c + θ_s K_s and the clamped sets of a femur's model (full DOFs)."""

    system: fe.FESystem
    femur: FemurModel
    patterns: np.ndarray
    drill_point: sp.csr_matrix
    K_c: sp.bsr_matrix
    K_s: sp.bsr_matrix
    _outer: np.ndarray = field(repr=False)
    _sets: dict[tuple[int, int], fe.Constraints] = field(default_factory=dict, repr=False)
    _lengths: dict[float, tuple[tuple[int, int], fe.Constraints]] = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, model) -> "StiffnessFamily":
        """From a :class:`femstudy.GlobalModel`: K_s = K(cancellous × 2) − K, K_c = K − K_s
        (one more assembly)."""
        mats = model.case.materials.to_fe()
        doubled = BoneMaterials(mats.cortical, replace(mats.cancellous, E_MPa=2 * mats.cancellous.E_MPa),
                                mats.cortical_model)
        other = fe.assemble(model.femur.mesh, doubled, order=model.system.order, long_axis=model.femur.frame.up)
        K_s = other.K_blocks - model.system.K_blocks  # 3×3 node blocks, as assembled and factorised
        K_c = model.system.K_blocks - K_s
        return cls(model.system, model.femur, np.asarray(model.patch.patterns), sp.csr_matrix(model.patch.mean),
                   K_c, K_s, outer_faces(model.femur.mesh, model.femur.frame))

    def constraints(self, clamp_length_mm: float) -> tuple[tuple, fe.Constraints]:
        """The clamped set of a length: its key (clamped node counts) and constraints (cached)."""
        if clamp_length_mm in self._lengths:
            return self._lengths[clamp_length_mm]
        masks = clamp_masks(self.femur.mesh, self.femur.frame, self._outer, clamp_length_mm)
        key = (int(masks.proximal.sum()), int(masks.distal.sum()))
        if key not in self._sets:
            self._sets[key] = fe.clamp(self.system, masks)
        self._lengths[clamp_length_mm] = key, self._sets[key]
        return self._lengths[clamp_length_mm]

    def factorize(self, p: StiffnessPoint, solver: str = "auto") -> fe.FactorizedSystem:
        _, bc = self.constraints(p.clamp_length_mm)
        K = p.cortical * self.K_c + p.cancellous * self.K_s
        return fe.factorize(replace(self.system, K_blocks=K), bc, solver)

    def solve(self, p: StiffnessPoint, solver: str = "auto") -> np.ndarray:
        """(n_dofs, 2) unit responses at ``p`` by a factorisation."""
        fs = self.factorize(p, solver)
        try:
            return fs.bc.expand(fs.factor.solve(self.patterns[fs.bc.free]))
        finally:
            fs.factor.close()


@dataclass
class ClampBasis:
    """The reduced basis of one clamped set (see the module docstring).

    V : (n_dofs, r) orthonormal; snapshots : (k, 2) modulus factors solved
    Gc, Gs : Vᵀ K_c V, Vᵀ K_s V; VP : Vᵀ P; dual : Wᵀ A⁻¹ W, W = [K_c V, K_s V, P]
    point : λ_max(D A⁻¹ Dᵀ), D the drill point's footprint mean
    """

    V: np.ndarray
    snapshots: np.ndarray
    Gc: np.ndarray
    Gs: np.ndarray
    VP: np.ndarray
    dual: np.ndarray
    point: float

    def coordinates(self, cortical: float, cancellous: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reduced coordinates y (r, 2), energy-norm error bounds and energy norms (no full vector)."""
        A = cortical * self.Gc + cancellous * self.Gs
        y = np.linalg.solve(A, self.VP)
        c = np.vstack([cortical * y, cancellous * y, -np.eye(2)])  # r = W c
        error = np.sqrt(np.maximum(np.einsum("ij,ik,kj->j", c, self.dual, c), 0.0) / min(cortical, cancellous))
        energy = np.sqrt(np.einsum("ij,ik,kj->j", y, A, y))
        return y, error, energy

    def evaluate(self, cortical: float, cancellous: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit responses (n_dofs, 2), their energy-norm error bounds and energy norms."""
        y, error, energy = self.coordinates(cortical, cancellous)
        return self.V @ y, error, energy

    def arrays(self, prefix: str) -> dict:
        return {f"{prefix}{k}": v for k, v in self.__dict__.items()}

    @classmethod
    def from_arrays(cls, data, prefix: str) -> "ClampBasis":
        return cls(**{k: (float(data[prefix + k]) if k == "point" else data[prefix + k])
                      for k in cls.__dataclass_fields__})


def build(family: StiffnessFamily, clamp_length_mm: float, moduli: list, solver: str = "auto",
          nominal_fields: np.ndarray | None = None, rtol: float = RTOL,
          max_snapshots: int = MAX_SNAPSHOTS) -> tuple[ClampBasis, int]:
    """The basis of one clamped set, trained greedily on ``moduli`` ((θ_c, θ_s) pairs); returns
    it and the factorisations it took. ``nominal_fields`` (the study's unit responses, when this
    is the case's own clamped set) saves solving θ = 1."""
    one = StiffnessPoint(1.0, 1.0, clamp_length_mm)
    fs = family.factorize(one, solver)  # A = K_ff(1): the dual norms, and the first snapshot
    factorisations = 1
    try:
        free = fs.bc.free
        first = nominal_fields if nominal_fields is not None else fs.bc.expand(fs.factor.solve(family.patterns[free]))
        V = np.zeros((family.system.n_dofs, 0))
        snapshots: list = []
        AinvW = np.zeros((len(free), 0))
        Dt = family.drill_point[:, free].T.toarray()
        point = float(np.linalg.eigvalsh(Dt.T @ fs.factor.solve(Dt)).max())
        P = family.patterns[free]
        AinvP = fs.factor.solve(P)

        def grow(fields, theta):
            nonlocal V, AinvW
            X = fields - V @ (V.T @ fields)
            X = X - V @ (V.T @ X)
            Q, R = np.linalg.qr(X)
            keep = np.abs(np.diag(R)) > 1e-10 * np.linalg.norm(fields, axis=0).max()
            new = Q[:, keep]
            V = np.hstack([V, new])
            snapshots.append(theta)
            AinvW = np.hstack([AinvW, fs.factor.solve(np.hstack([(family.K_c @ new)[free], (family.K_s @ new)[free]]))])

        def assemble_basis() -> ClampBasis:
            KcV, KsV = family.K_c @ V, family.K_s @ V
            W = np.hstack([KcV[free], KsV[free], P])
            # AinvW holds the columns in the order they were added: [Kc v1, Ks v1, Kc v2, ...] per block
            order = _block_order(AinvW.shape[1] // 2, [len(b) for b in blocks])
            Z = np.hstack([AinvW[:, order], AinvP])
            return ClampBasis(V, np.array(snapshots, float), V.T @ KcV, V.T @ KsV, V.T @ family.patterns, W.T @ Z,
                              point)

        blocks: list = []

        def add(fields, theta):
            before = V.shape[1]
            grow(fields, theta)
            blocks.append(range(before, V.shape[1]))

        add(first, (1.0, 1.0))
        basis = assemble_basis()
        while len(snapshots) < max_snapshots:
            worst, where = 0.0, None
            for theta in moduli:
                _, error, energy = basis.coordinates(*theta)
                rel = float(np.max(error / np.maximum(energy, 1e-300)))
                if rel > worst:
                    worst, where = rel, theta
            log.info("reduced basis at clamp %.3g mm: %d snapshots, largest relative energy error %.2g",
                     clamp_length_mm, len(snapshots), worst)
            if worst <= rtol or where is None:
                break
            add(family.solve(StiffnessPoint(*where, clamp_length_mm), solver), tuple(where))
            factorisations += 1
            basis = assemble_basis()
    finally:
        fs.factor.close()
    return basis, factorisations


def _block_order(n_vectors: int, sizes: list) -> np.ndarray:
    """Column order turning per-block [K_c new, K_s new] pairs into [K_c V, K_s V]."""
    kc, ks, start = [], [], 0
    for size in sizes:
        kc += list(range(start, start + size))
        ks += list(range(start + size, start + 2 * size))
        start += 2 * size
    assert len(kc) == n_vectors
    return np.array(kc + ks, dtype=int)


@dataclass
class ReducedBases:
    """The bases of every clamped set a design visits, keyed by the set."""

    family: StiffnessFamily
    bases: dict[tuple[int, int], ClampBasis]
    factorisations: int

    def evaluate(self, p: StiffnessPoint) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Unit responses, energy errors, energy norms and the drill-point factor √λ_max(D A⁻¹ Dᵀ)."""
        key, _ = self.family.constraints(p.clamp_length_mm)
        basis = self.bases.get(key)
        if basis is None:
            raise KeyError(key)
        fields, error, energy = basis.evaluate(p.cortical, p.cancellous)
        return fields, error, energy, float(np.sqrt(basis.point / min(p.cortical, p.cancellous)))

    def save(self, path) -> None:
        arrays = {}
        for k, (key, b) in enumerate(self.bases.items()):
            arrays.update(b.arrays(f"b{k}_"))
            arrays[f"b{k}_key"] = np.array(key)
        arrays["count"] = np.array(len(self.bases))
        arrays["factorisations"] = np.array(self.factorisations)
        np.savez(path, **arrays)

    @classmethod
    def load(cls, family: StiffnessFamily, data) -> "ReducedBases":
        bases = {tuple(int(x) for x in data[f"b{k}_key"]): ClampBasis.from_arrays(data, f"b{k}_")
                 for k in range(int(data["count"]))}
        return cls(family, bases, int(data["factorisations"]))


def train(family: StiffnessFamily, points: list, nominal: StiffnessPoint, nominal_fields: np.ndarray,
          solver: str = "auto") -> ReducedBases:
    """A basis for every clamped set among ``points`` (the design's stiffness points)."""
    groups: dict = {}
    for p in points + [nominal]:
        key, _ = family.constraints(p.clamp_length_mm)
        groups.setdefault(key, (p.clamp_length_mm, set()))[1].add((p.cortical, p.cancellous))
    nominal_key, _ = family.constraints(nominal.clamp_length_mm)
    bases, total = {}, 0
    for key, (length, moduli) in groups.items():
        basis, n = build(family, length, sorted(moduli), solver,
                         nominal_fields if key == nominal_key else None)
        bases[key] = basis
        total += n
    log.info("reduced bases: %d clamped set(s), %d factorisations", len(bases), total)
    return ReducedBases(family, bases, total)
