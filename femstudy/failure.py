"""Failure assessment of bone near the drilled hole: how far the loads could be scaled before
a strength criterion is met (the strength ratio), per region, from the stress tensor.

Cortical bone is transversely isotropic in strength as in stiffness: strong along the long
axis L, weak across it (T), weaker in tension than in compression. Its criterion is the
Tsai–Wu quadratic (Tsai & Wu 1971, J Compos Mater 5:58–80; used for cortical bone by
Cezayirlioglu et al. 1985, J Biomech 18:61–69) in the bone's frame, with the strengths of
thesis Table 2-4 (human femoral cortex; the values are Reilly & Burstein's 1975, J Biomech
8:393–405):

    F(σ) = F_L σ_L + F_T (σ_1 + σ_2) + F_LL σ_L² + F_TT (σ_1² + σ_2²) + 2 F_LT σ_L (σ_1 + σ_2)
           + 2 F_12 σ_1 σ_2 + (τ_L1² + τ_L2²)/S² + τ_12²/S_T²

    F_L = 1/X_t − 1/X_c, F_LL = 1/(X_t X_c), F_T = 1/Y_t − 1/Y_c, F_TT = 1/(Y_t Y_c),
    F_LT = −½ √(F_LL F_TT), F_12 = −½ F_TT, S_T² = 1/(2 (F_TT − F_12))

with X (longitudinal), Y (transverse) tension/compression strengths and S the shear strength;
σ_1, σ_2, τ_12 act in the transverse plane (which is isotropic). Failure when F ≥ 1; the
strength ratio is the factor λ with F(λσ) = 1: λ = (−b + √(b² + 4a)) / (2a), a the quadratic
and b the linear part of F(σ). Cancellous bone, isotropic and of widely varying strength, is
judged by its von Mises stress against the Table 2-5 mean ultimate strength (7.56 MPa; range
0.56–22.9 MPa, reported beside). Beside the stress criteria, cortical bone is also judged by
the maximum principal strain criterion (:func:`strain_ratio`). docs/failure.md gives the choices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femstudy import thesis
from femstudy.fe.materials import frame_with_axis


@dataclass(frozen=True)
class CorticalStrength:
    """Strengths [MPa]: longitudinal tension/compression X_t, X_c, transverse Y_t, Y_c, shear S."""

    X_t: float = thesis.CORTICAL_STRENGTH_MPA["longitudinal_tension_ultimate"]
    X_c: float = thesis.CORTICAL_STRENGTH_MPA["longitudinal_compression_ultimate"]
    Y_t: float = thesis.CORTICAL_STRENGTH_MPA["transverse_tension_ultimate"]
    Y_c: float = thesis.CORTICAL_STRENGTH_MPA["transverse_compression_ultimate"]
    S: float = thesis.CORTICAL_STRENGTH_MPA["shear_ultimate"]
    source: str = "thesis Table 2-4 (Reilly & Burstein 1975), human femoral cortex, ultimate"


def _voigt_to_tensor(stress: np.ndarray) -> np.ndarray:
    """Voigt (..., 6) [xx, yy, zz, yz, xz, xy] → tensors (..., 3, 3)."""
    s = np.asarray(stress, float)
    t = np.empty(s.shape[:-1] + (3, 3))
    t[..., 0, 0], t[..., 1, 1], t[..., 2, 2] = s[..., 0], s[..., 1], s[..., 2]
    t[..., 1, 2] = t[..., 2, 1] = s[..., 3]
    t[..., 0, 2] = t[..., 2, 0] = s[..., 4]
    t[..., 0, 1] = t[..., 1, 0] = s[..., 5]
    return t


def cortical_strength_ratio(stress: np.ndarray, long_axis, strength: CorticalStrength = CorticalStrength()
                            ) -> np.ndarray:
    """Tsai–Wu strength ratio λ (module docstring) of Voigt stresses (..., 6) [MPa] for bone whose
    long axis is ``long_axis`` (a 3-vector, or one per stress); inf where unloaded."""
    R = frame_with_axis(np.asarray(long_axis, float))  # columns e1, e2, L
    local = np.einsum("...ia,...ij,...jb->...ab", R, _voigt_to_tensor(stress), R)
    s1, s2, sL = local[..., 0, 0], local[..., 1, 1], local[..., 2, 2]
    t12, t1L, t2L = local[..., 0, 1], local[..., 0, 2], local[..., 1, 2]
    X_t, X_c, Y_t, Y_c, S = strength.X_t, strength.X_c, strength.Y_t, strength.Y_c, strength.S
    F_L, F_LL = 1 / X_t - 1 / X_c, 1 / (X_t * X_c)
    F_T, F_TT = 1 / Y_t - 1 / Y_c, 1 / (Y_t * Y_c)
    F_LT, F_12 = -0.5 * np.sqrt(F_LL * F_TT), -0.5 * F_TT
    quadratic = (F_LL * sL ** 2 + F_TT * (s1 ** 2 + s2 ** 2) + 2 * F_LT * sL * (s1 + s2) + 2 * F_12 * s1 * s2
                 + (t1L ** 2 + t2L ** 2) / S ** 2 + 2 * (F_TT - F_12) * t12 ** 2)
    linear = F_L * sL + F_T * (s1 + s2)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (-linear + np.sqrt(linear ** 2 + 4 * quadratic)) / (2 * quadratic)
    return np.where(quadratic > 0, ratio, np.inf)


@dataclass(frozen=True)
class CorticalStrainLimits:
    """Limits of the maximum principal strain criterion for cortical bone [-]: the largest
    principal strain against ``tension``, the smallest against −``compression``.

    The values are the human femoral cortical tissue's yield strains of Bayraktar et al. (2004,
    J Biomech 37:27–35), the limits with which Schileo et al. (2008, J Biomech 41:356–367)
    predicted the fracture load and site of femurs tested to failure. The thesis (Table 2-4)
    gives ultimate tensile strains only — 0.031 along the bone, 0.007 across it — and none in
    compression; the tensile limit here is its transverse value to within 5 % (docs/failure.md).
    """

    tension: float = 0.0073
    compression: float = 0.0104
    source: str = ("maximum principal strain (Schileo et al. 2008) with the yield strains of Bayraktar et al. "
                   "2004: 0.73 % tension, 1.04 % compression")


def strain_ratio(max_principal_strain: np.ndarray, min_principal_strain: np.ndarray,
                 limits: CorticalStrainLimits = CorticalStrainLimits()) -> np.ndarray:
    """The load factor λ at which the maximum principal strain criterion is met:
    λ = min(ε_t / ε_1, ε_c / (−ε_3)) over the terms that are loaded (ε_1 > 0, ε_3 < 0) [-];
    inf where unstrained. Strains scale with the loads (linear elasticity)."""
    e1 = np.asarray(max_principal_strain, float)
    e3 = np.asarray(min_principal_strain, float)
    with np.errstate(divide="ignore"):
        tension = np.where(e1 > 0, limits.tension / np.where(e1 > 0, e1, 1.0), np.inf)
        compression = np.where(e3 < 0, limits.compression / np.where(e3 < 0, -e3, 1.0), np.inf)
    return np.minimum(tension, compression)


def cancellous_strength_ratio(von_mises_MPa: np.ndarray, strength_MPa: float = thesis.CANCELLOUS_STRENGTH_MPA["mean"]
                              ) -> np.ndarray:
    """Strength / von Mises stress [-] for cancellous bone (Table 2-5 mean by default)."""
    vm = np.asarray(von_mises_MPa, float)
    with np.errstate(divide="ignore"):
        return np.where(vm > 0, strength_MPa / vm, np.inf)
