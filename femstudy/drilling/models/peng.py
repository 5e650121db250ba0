"""Peng's simplified model (Eqs 2.20–2.21): constant cutting loads per material.

R_a, the material strength in the torque, is Table 2-4's longitudinal tensile strength for the
cortex and Table 2-5's mean for cancellous bone.
"""

import numpy as np

from femstudy import thesis
from femstudy.drilling import literature
from femstudy.drilling.registry import LoadModel, LoadParts, register

CORTICAL_TENSILE_STRENGTH_MPA = thesis.CORTICAL_STRENGTH_MPA["longitudinal_tension_ultimate"]
CANCELLOUS_STRENGTH_MPA = thesis.CANCELLOUS_STRENGTH_MPA["mean"]


def peng_parts(cond, t_s, depth_mm, content) -> LoadParts:
    """Peng's thrust and torque in the cortex and in cancellous bone; no evacuation part."""
    d, a, h, drill, bone = depth_mm, cond.feed_per_rev_mm, cond.cortex_mm, cond.drill, cond.bone
    in_cortex, in_cancellous = (d > 0) & (d <= h), d > h
    beyond = cond.beyond_cortex == "cancellous"  # nothing to cut in the canal
    F = in_cortex * literature.peng_thrust(a, bone.u1_MPa, drill) + in_cancellous * literature.peng_thrust(
        a, cond.u2_MPa, drill)
    T = (in_cortex * literature.peng_torque(a, CORTICAL_TENSILE_STRENGTH_MPA, drill)
         + in_cancellous * beyond * literature.peng_torque(a, CANCELLOUS_STRENGTH_MPA, drill))
    zero = np.zeros_like(np.asarray(d, float))
    return LoadParts(np.asarray(F, float), np.asarray(T, float), zero, zero)


register(LoadModel("peng", "Peng simplified (Eqs 2.20-2.21)", "tab:red", peng_parts, uses=("study",), rank=3))
