"""Cutting plus chip evacuation (the chip-clogging model, Eqs 3.16/3.19), the study's default.

    F(d) = F_cut(d) + F_o (exp(p z) − 1) · s(d)
    T(d) = T_cut(d) + R μ_w l_w F_o / M · (exp(p z) − 1) · s(d)

F_cut, T_cut are Allotta's (:mod:`.allotta`); F_o = F_cut at full engagement, so in the cortex
F = F_o exp(p z) as Eq 3.16, and the evacuation torque is Eq 3.19. z = (min(d, h) − l)/D ≥ 0 is
the depth past full engagement in diameters, frozen at breakthrough; s(d) is the share of the
tip cone still in cortex, or, with a breakthrough release time τ, 1 − (t − h/f)/τ clipped to
[0, 1] (docs/load-models.md).
"""

import numpy as np

from femstudy.drilling import clogging
from femstudy.drilling.models.allotta import cutting_parts
from femstudy.drilling.registry import LoadModel, LoadParts, register


def clogging_parts(cond, t_s, depth_mm, content) -> LoadParts:
    """Allotta's cutting parts and the chip-evacuation parts of Eqs 3.16/3.19."""
    cutting = cutting_parts(cond, t_s, depth_mm, content)
    d, h, drill = depth_mm, cond.cortex_mm, cond.drill
    F0, _ = cond.static_allotta()
    mu_f, mu_w = cond.friction
    l = drill.cone_length_mm
    z = np.maximum((np.minimum(d, h) - l) / drill.diameter_mm, 0.0)
    in_cortex = np.clip(np.minimum(d, h) - np.maximum(d - l, 0.0), 0.0, l) / l
    if content.release_s is not None:  # released within release_s of breakthrough (t = h/f)
        in_cortex = np.clip(1 - (t_s - h / cond.feed_mm_s) / content.release_s, 0.0, 1.0) * (d > 0)
    return LoadParts(cutting.cutting_thrust_N, cutting.cutting_torque_Nmm,
                     (clogging.thrust(z, F0, mu_f, mu_w, drill) - F0) * in_cortex,
                     clogging.torque(z, F0, mu_f, mu_w, drill) * in_cortex)


register(LoadModel("clogging", "cutting + chip evacuation (Eqs 3.16/3.19)", "tab:orange", clogging_parts, rank=1))
