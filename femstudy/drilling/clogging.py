"""Chip-evacuation (flute clogging) thrust and torque, thesis §3.2.1.

A force balance on the granular chip column in a flute (Eqs 3.1–3.13) makes the axial chip
pressure grow exponentially with the dimensionless depth z = depth / D, counted from full
tip engagement:

    M    = μ_f (l_f + l_h + l_r) + l_w μ_f μ_w sin θ                    (Eq 3.14 / 4.3)
    p    = η M D / S                        (growth exponent per diameter of depth)
    F(z) = F_o exp(p z)                                                 (Eq 3.16 / 4.1)
    T(z) = R μ_w l_w F_o / M · (exp(p z) − 1)                           (Eq 3.19 / 4.2)

F includes the cutting force (F(0) = F_o), while T is the evacuation torque alone
(T(0) = 0); :mod:`femstudy.drilling.history` adds it to the cutting torque. As in the
thesis's calibration, F_o and the measured loads are totals over both flutes.

Units: lengths mm, S mm², F N, T N·mm; μ, η, p and z dimensionless.
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.drilling.drill import Drill


def friction_factor(mu_f: float, mu_w: float, drill: Drill = Drill()) -> float:
    """M [mm] of Eq 3.14."""
    sin_theta = math.sin(math.radians(drill.face_angle_deg))
    return mu_f * drill.flute_length_sum_mm + drill.wall_mm * mu_f * mu_w * sin_theta


def growth_exponent(mu_f: float, mu_w: float, drill: Drill = Drill()) -> float:
    """p = η M D / S, the growth of ln F per diameter of depth (Eq 3.13)."""
    return drill.eta * friction_factor(mu_f, mu_w, drill) * drill.diameter_mm / drill.flute_area_mm2


def thrust(z, initial_force_N: float, mu_f: float, mu_w: float, drill: Drill = Drill()):
    """F_c(z) = F_o exp(p z) [N] (Eq 3.16), vectorised in z."""
    return initial_force_N * np.exp(growth_exponent(mu_f, mu_w, drill) * np.asarray(z, float))


def torque(z, initial_force_N: float, mu_f: float, mu_w: float, drill: Drill = Drill()):
    """T_c(z) = R μ_w l_w F_o / M (exp(p z) − 1) [N·mm] (Eq 3.19), vectorised in z."""
    M = friction_factor(mu_f, mu_w, drill)
    p = growth_exponent(mu_f, mu_w, drill)
    scale = drill.radius_mm * mu_w * drill.wall_mm * initial_force_N / M
    return scale * np.expm1(p * np.asarray(z, float))


def torque_integrand(zeta, initial_force_N: float, mu_f: float, mu_w: float,
                     drill: Drill = Drill()):
    """dT_c/dz = R μ_w η l_w D (F_o/S) exp(p ζ) [N·mm per unit z] (Eq 3.18)."""
    p = growth_exponent(mu_f, mu_w, drill)
    return (drill.radius_mm * mu_w * drill.eta * drill.wall_mm * drill.diameter_mm
            * initial_force_N / drill.flute_area_mm2 * np.exp(p * np.asarray(zeta, float)))


def sensitivities(mu_f: float, mu_w: float, z: float, drill: Drill = Drill()) -> dict:
    """Normalised sensitivities S_μ = (μ/ψ) ∂ψ/∂μ (Eq 5.7) of F_c and T_c, analytically.

    With x = p z and g = x·exp(x)/(exp(x) − 1), and since M is proportional to μ_f:

        S(F, μ_f) = x,                       S(F, μ_w) = x · w,
        S(T, μ_f) = g − 1,                   S(T, μ_w) = 1 − w + w g,

    where w = l_w μ_f μ_w sin θ / M is the wall's share of M. The ratio
    S(F, μ_w)/S(F, μ_f) = w does not depend on the depth z.
    """
    M = friction_factor(mu_f, mu_w, drill)
    wall_share = drill.wall_mm * mu_f * mu_w * math.sin(math.radians(drill.face_angle_deg)) / M
    x = growth_exponent(mu_f, mu_w, drill) * z
    g = x * math.exp(x) / math.expm1(x) if x > 0 else 1.0
    return {
        "force_mu_f": x,
        "force_mu_w": x * wall_share,
        "torque_mu_f": g - 1.0,
        "torque_mu_w": 1.0 - wall_share + wall_share * g,
    }
