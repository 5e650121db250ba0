"""Elastic stiffness matrices per element, in Voigt notation.

Stress and strain vectors are ordered ``[xx, yy, zz, yz, xz, xy]``; strains use engineering
shear (γ = 2ε), so σ = D ε with D the 6×6 stiffness [MPa]. Region codes follow
:mod:`femstudy.femur_mesh`: the cortical material applies to CORTICAL, the cancellous one
to both cancellous regions.

The optional transversely isotropic cortex (``BoneMaterials.cortical_model =
"transversely_isotropic"``) uses :data:`CORTICAL_TRANSVERSELY_ISOTROPIC`; the choice of
values, and why the thesis's Table 2-2 is not used, is explained in docs/solver.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femstudy.errors import require
from femstudy.femur_mesh import CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL
from femstudy.materials import BoneMaterials


@dataclass(frozen=True)
class TransverselyIsotropic:
    """Transversely isotropic elastic constants; L is the symmetry (long) axis, T the plane.

    E_T_MPa, E_L_MPa : Young's moduli across and along the axis [MPa]
    nu_TT            : Poisson's ratio in the transverse plane
    nu_LT            : lateral contraction under stress along L (−ε_T/ε_L), thesis ν31, ν32
    G_LT_MPa         : shear modulus in planes containing the axis [MPa]
    The transverse shear modulus is fixed by isotropy in the plane: G_TT = E_T / (2(1 + ν_TT)).
    """

    E_T_MPa: float
    E_L_MPa: float
    nu_TT: float
    nu_LT: float
    G_LT_MPa: float

    @property
    def G_TT_MPa(self) -> float:
        return self.E_T_MPa / (2.0 * (1.0 + self.nu_TT))

    def stiffness(self) -> np.ndarray:
        """D (6×6) [MPa] in the local frame with axis 3 = L, by inverting the compliance
        S = [[1/E_T, −ν_TT/E_T, −ν_LT/E_L], [., 1/E_T, −ν_LT/E_L], [., ., 1/E_L]] ⊕
        diag(1/G_LT, 1/G_LT, 1/G_TT)."""
        ET, EL, vTT, vLT = self.E_T_MPa, self.E_L_MPa, self.nu_TT, self.nu_LT
        S = np.zeros((6, 6))
        S[:3, :3] = [[1 / ET, -vTT / ET, -vLT / EL],
                     [-vTT / ET, 1 / ET, -vLT / EL],
                     [-vLT / EL, -vLT / EL, 1 / EL]]
        S[3, 3] = S[4, 4] = 1 / self.G_LT_MPa
        S[5, 5] = 1 / self.G_TT_MPa
        require(np.all(np.linalg.eigvalsh(S) > 0),
                f"transversely isotropic constants {self} are not positive definite")
        return np.linalg.inv(S)


#: Human femoral cortex (thesis Tables 2-1 and 2-3, tension column), reduced to transverse
#: isotropy: E_T = mean(E1, E2) = 12.7 GPa, E_L = E3 = 20.0 GPa, ν_TT = mean(ν12, ν21) = 0.40,
#: ν_LT = mean(ν31, ν32) = 0.36; G_LT = mean(G13, G23) = 5.92 GPa from the ultrasonic data set
#: that those E and ν come from (Ashman et al. 1984), because Table 2-2 repeats the Young's
#: moduli as shear moduli. docs/solver.md gives the reasoning.
CORTICAL_TRANSVERSELY_ISOTROPIC = TransverselyIsotropic(
    E_T_MPa=12.7e3, E_L_MPa=20.0e3, nu_TT=0.40, nu_LT=0.36, G_LT_MPa=5.92e3)


def isotropic_stiffness(E_MPa: float, nu: float) -> np.ndarray:
    """D (6×6) [MPa] of an isotropic solid: λ = Eν/((1+ν)(1−2ν)), μ = E/(2(1+ν)),
    D = λ 1⊗1 + 2μ I on the normal block and μ on the (engineering) shear diagonal."""
    require(E_MPa > 0 and -1 < nu < 0.5, f"E = {E_MPa} MPa, nu = {nu} is not a stable isotropic material")
    lam = E_MPa * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E_MPa / (2 * (1 + nu))
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2 * mu
    D[np.arange(3, 6), np.arange(3, 6)] = mu
    return D


_VOIGT = np.array([[0, 5, 4], [5, 1, 3], [4, 3, 2]])  # tensor index pair -> Voigt index


def stiffness_tensor(D: np.ndarray) -> np.ndarray:
    """The elasticity tensor C_ijkl (..., 3, 3, 3, 3) [MPa] of Voigt stiffnesses D (..., 6, 6):
    C_ijkl = D[V(ij), V(kl)] (engineering shear, so no factors)."""
    D = np.asarray(D, float)
    return D[..., _VOIGT.ravel()[:, None], _VOIGT.ravel()[None, :]].reshape(D.shape[:-2] + (3, 3, 3, 3))


def rotate_stiffness(D: np.ndarray, R: np.ndarray) -> np.ndarray:
    """D' = D rotated by R: C'_ijkl = R_ia R_jb R_kc R_ld C_abcd, with the columns of R the
    local axes in global coordinates. Vectorised: R may be (..., 3, 3); returns (..., 6, 6)."""
    C = stiffness_tensor(D)
    Cg = np.einsum("...ia,...jb,...kc,...ld,abcd->...ijkl", R, R, R, R, C, optimize=True)
    i, j = np.array([0, 1, 2, 1, 0, 0]), np.array([0, 1, 2, 2, 2, 1])
    return Cg[..., i[:, None], j[:, None], i[None, :], j[None, :]]


def frame_with_axis(axis: np.ndarray) -> np.ndarray:
    """Orthonormal frames (..., 3, 3) whose third column is the unit ``axis`` (..., 3)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    helper = np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.cross(helper, a)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(a, e1)
    return np.stack([e1, e2, a], axis=-1)


@dataclass(frozen=True)
class ElementMaterials:
    """Material of every tetrahedron: ``D[index[e]]`` is its stiffness [MPa] (6×6) and
    ``density[e]`` its density [tonne/mm³]."""

    D: np.ndarray
    index: np.ndarray
    density: np.ndarray
    description: str


def element_materials(region: np.ndarray, materials: BoneMaterials, long_axis=None) -> ElementMaterials:
    """Per-element stiffness and density from :class:`femstudy.materials.BoneMaterials`.

    ``long_axis`` (a unit vector, or one per element) orients the transversely isotropic
    cortex; it is required only for that model.
    """
    region = np.asarray(region)
    known = np.isin(region, [CORTICAL, CANCELLOUS_PROXIMAL, CANCELLOUS_DISTAL])
    require(known.all(), f"mesh has unknown region codes {sorted(set(region[~known].tolist()))}; "
                         f"expected {CORTICAL}, {CANCELLOUS_PROXIMAL}, {CANCELLOUS_DISTAL}")
    cortical = region == CORTICAL
    cort, canc = materials.cortical, materials.cancellous
    density = np.where(cortical, cort.density_t_mm3, canc.density_t_mm3)
    D_canc = isotropic_stiffness(canc.E_MPa, canc.nu)
    cancellous_text = f"cancellous E = {canc.E_MPa / 1e3:g} GPa, ν = {canc.nu:g}"
    if materials.cortical_model == "isotropic":
        D = np.stack([isotropic_stiffness(cort.E_MPa, cort.nu), D_canc])
        return ElementMaterials(D, np.where(cortical, 0, 1), density,
                                f"cortical E = {cort.E_MPa / 1e3:g} GPa, ν = {cort.nu:g}; {cancellous_text}")
    require(long_axis is not None, "the transversely isotropic cortex needs the bone's long axis")
    ti = CORTICAL_TRANSVERSELY_ISOTROPIC
    axis = np.asarray(long_axis, float)
    if axis.ndim == 1:
        D = np.stack([rotate_stiffness(ti.stiffness(), frame_with_axis(axis)), D_canc])
        index = np.where(cortical, 0, 1)
    else:
        require(axis.shape == (len(region), 3), "a per-element long axis needs one 3-vector per tetrahedron")
        cells = np.flatnonzero(cortical)
        D = np.concatenate([rotate_stiffness(ti.stiffness(), frame_with_axis(axis[cells])), D_canc[None]])
        index = np.full(len(region), len(cells))
        index[cells] = np.arange(len(cells))
    return ElementMaterials(D, index, density,
                            f"cortical transversely isotropic E_T = {ti.E_T_MPa / 1e3:g} GPa, "
                            f"E_L = {ti.E_L_MPa / 1e3:g} GPa, ν_TT = {ti.nu_TT:g}, ν_LT = {ti.nu_LT:g}, "
                            f"G_LT = {ti.G_LT_MPa / 1e3:g} GPa; {cancellous_text}")
