"""Thrust and torque models from the literature that the thesis compares against (§2.6).

Both are depth-independent: a constant load while the drill cuts a given material.
Units: f mm/s, N rpm, ρ g/cm³, a mm/rev, D mm, u and R_a MPa, F N, T N·mm.
"""

from __future__ import annotations

import math

from femstudy.drilling.drill import Drill

#: Regression constants of Chi's thrust model (Eq 2.24 with the digits of the text).
CHI_CONSTANTS = {"C_T": 134.6097, "C_N": -0.3327, "C_f": 0.5189, "C_D": 1.1841}


def chi_thrust(feed_mm_s: float, spindle_rpm: float, density_g_cm3: float) -> float:
    """Chi's empirical thrust F = C_T N^C_N f^C_f ρ^C_D [N] (Eqs 2.22–2.24). No torque."""
    c = CHI_CONSTANTS
    return c["C_T"] * spindle_rpm ** c["C_N"] * feed_mm_s ** c["C_f"] * density_g_cm3 ** c["C_D"]


def peng_thrust(feed_per_rev_mm: float, specific_energy_MPa: float, drill: Drill = Drill()) -> float:
    """Peng's simplified thrust F = u a (D/2) sin(β/2) [N] (Eq 2.20).

    It equals Allotta's full-engagement thrust (Eq 2.18 with the whole cone in one material).
    """
    return specific_energy_MPa * feed_per_rev_mm * drill.radius_mm * math.sin(drill.half_angle_rad)


def peng_torque(feed_per_rev_mm: float, tensile_strength_MPa: float, drill: Drill = Drill()) -> float:
    """Peng's simplified torque T = 5 R_a a D²/2 [N·mm] (Eq 2.21, as printed).

    R_a is the "unitary ultimate tensile load", read here as the ultimate tensile strength
    of the material. As printed, with R_a = 133 MPa (Table 2-4), this is about six times
    Allotta's full-engagement torque u1 D² a/8; docs/load-models.md discusses it.
    """
    return 5.0 * tensile_strength_MPa * feed_per_rev_mm * drill.diameter_mm ** 2 / 2
