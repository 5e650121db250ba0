"""Allotta's cutting model (Eqs 2.18–2.19): the cone's cutting loads only, no chip evacuation."""

import numpy as np

from femstudy.drilling import allotta
from femstudy.drilling.registry import LoadModel, LoadParts, register


def cutting_parts(cond, t_s, depth_mm, content) -> LoadParts:
    """Allotta's thrust and torque of the engaged cone at each depth (u1 in the cortex, the
    conditions' u2 beyond it); no evacuation part."""
    a, h, drill, bone = cond.feed_per_rev_mm, cond.cortex_mm, cond.drill, cond.bone
    F = allotta.thrust(depth_mm, a, h, bone.u1_MPa, cond.u2_MPa, drill)
    T = allotta.torque(depth_mm, a, h, bone.u1_MPa, cond.u2_MPa, drill)
    zero = np.zeros_like(np.asarray(depth_mm, float))
    return LoadParts(F, T, zero, zero)


register(LoadModel("allotta", "Allotta cutting (Eqs 2.18-2.19)", "tab:blue", cutting_parts, rank=0))
