"""Allotta's cutting thrust and torque through a cortical layer into cancellous bone.

Eqs 2.18–2.19 of the thesis integrate the specific cutting energy u over the part of the
tip cone that is in each material. Written with the tip at depth d below the bone surface
(so the cone occupies depths y ∈ [d − l, d] and its radius at y is (d − y)·tan(β/2)):

    F(d) = a sin(β/2) tan(β/2) ∫ u(y) dy,          (Eq 2.18)
    T(d) = a tan²(β/2)       ∫ u(y) (d − y) dy,    (Eq 2.19)

with u = 0 above the surface (air), u = u1 in the cortex 0 ≤ y < h and u = u2 below it.
This one expression gives every phase of a unicortical hole and is continuous across
them: the entry ramp (F linear and T parabolic in d, Fig 3-4), full engagement
(F = a sin(β/2) tan(β/2) u1 l, T = a tan²(β/2) u1 l²/2 = u1 D² a/8, Eq 2.3) and the
cortex-to-cancellous transition (Eqs 2.18–2.19 with x_b = h − (d − l)). Setting u2 = 0
gives the exit of a cortex into air.

Units: depth and lengths mm, a mm/rev, u N/mm² (MPa), F N, T N·mm.
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.drilling.drill import Drill


def _cone_integrals(depth_mm, cortex_mm: float, l: float):
    """Length and first moment (about the tip) of the cone inside cortex and cancellous.

    Returns (len_cortex, len_cancellous, mom_cortex, mom_cancellous) with
    len = ∫ dy and mom = ∫ (d − y) dy over the cone's overlap with each layer.
    """
    d = np.asarray(depth_mm, dtype=float)
    base = d - l

    def overlap(lo, hi):
        a = np.clip(base, lo, hi)
        b = np.clip(d, lo, hi)
        length = b - a
        moment = ((d - a) ** 2 - (d - b) ** 2) / 2
        return length, moment

    len_c, mom_c = overlap(0.0, cortex_mm)
    len_s, mom_s = overlap(cortex_mm, np.inf)
    return len_c, len_s, mom_c, mom_s


def thrust(depth_mm, feed_per_rev_mm: float, cortex_mm: float, u1: float, u2: float,
           drill: Drill = Drill()):
    """Allotta cutting thrust F(d) [N] at tip depth d [mm] (Eq 2.18), vectorised in d."""
    half = drill.half_angle_rad
    len_c, len_s, _, _ = _cone_integrals(depth_mm, cortex_mm, drill.cone_length_mm)
    return feed_per_rev_mm * math.sin(half) * math.tan(half) * (u1 * len_c + u2 * len_s)


def torque(depth_mm, feed_per_rev_mm: float, cortex_mm: float, u1: float, u2: float,
           drill: Drill = Drill()):
    """Allotta cutting torque T(d) [N·mm] at tip depth d [mm] (Eq 2.19), vectorised in d."""
    half = drill.half_angle_rad
    _, _, mom_c, mom_s = _cone_integrals(depth_mm, cortex_mm, drill.cone_length_mm)
    return feed_per_rev_mm * math.tan(half) ** 2 * (u1 * mom_c + u2 * mom_s)


def full_engagement(feed_per_rev_mm: float, u1: float, drill: Drill = Drill()):
    """Thrust [N] and torque [N·mm] with the whole cone in cortex: the static Allotta load.

    F = a sin(β/2) tan(β/2) u1 l and T = a tan²(β/2) u1 l²/2.
    """
    half = drill.half_angle_rad
    l = drill.cone_length_mm
    return (feed_per_rev_mm * math.sin(half) * math.tan(half) * u1 * l,
            feed_per_rev_mm * math.tan(half) ** 2 * u1 * l * l / 2)
