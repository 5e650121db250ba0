"""Chi's empirical thrust (Eq 2.24): a constant thrust per material, no torque."""

import numpy as np

from femstudy import thesis
from femstudy.drilling import literature
from femstudy.drilling.registry import LoadModel, LoadParts, register


def chi_parts(cond, t_s, depth_mm, content) -> LoadParts:
    """Chi's thrust in the cortex and in cancellous bone (by their densities); torque NaN."""
    d, h = depth_mm, cond.cortex_mm
    in_cortex, in_cancellous = (d > 0) & (d <= h), d > h
    in_cancellous = in_cancellous & (cond.beyond_cortex == "cancellous")  # nothing to cut in the canal
    F = (in_cortex * literature.chi_thrust(cond.feed_mm_s, cond.spindle_rpm, thesis.CORTICAL_DENSITY_G_CM3)
         + in_cancellous * literature.chi_thrust(cond.feed_mm_s, cond.spindle_rpm, thesis.CANCELLOUS_DENSITY_G_CM3))
    zero = np.zeros_like(np.asarray(d, float))
    return LoadParts(np.asarray(F, float), np.full_like(zero, np.nan), zero, zero)


register(LoadModel("chi", "Chi empirical thrust (Eq 2.24)", "tab:green", chi_parts, uses=(), rank=2))
