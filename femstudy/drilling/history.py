"""Thrust and torque histories of a unicortical hole for each load model.

The drill touches the bone at t = 0 and advances at the feed f, so the tip depth is
d = f·t [mm]. Phases: entry ramp 0 < d < l (tip cone entering the cortex), full engagement
l ≤ d ≤ h (cortex of thickness h), transition h < d < h + l (cone crossing into cancellous
bone), cancellous d ≥ h + l. "Breakthrough" is the instant the tip reaches the inner
surface of the cortex, d = h.

How cutting and chip evacuation combine (model "clogging"):

    F(d) = F_cut(d) + F_o (exp(p z) − 1) · s(d)
    T(d) = T_cut(d) + R μ_w l_w F_o / M · (exp(p z) − 1) · s(d)

F_cut, T_cut are Allotta's cutting loads (Eqs 2.18–2.19); F_o = F_cut at full engagement,
so in the cortex F = F_o exp(p z) exactly as Eq 3.16 and T = T_o + T_c(z) with T_c of
Eq 3.19 (which is zero at z = 0 and carries no cutting torque). z = (min(d, h) − l)/D ≥ 0
is the depth past full engagement in diameters, frozen at breakthrough. s(d) is the share
of the tip cone still in cortex (1 during full engagement): the evacuation load fades out
over the transition, as recorded forces fall to about zero once the drill is through.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from femstudy.drilling import allotta, clogging, literature
from femstudy.drilling.drill import Drill, feed_per_revolution
from femstudy.drilling.friction import BoneSet, builtin_bone_set
from femstudy.errors import require

MODELS = ("allotta", "clogging", "chi", "peng")
MODEL_TITLES = {
    "allotta": "Allotta cutting (Eqs 2.18-2.19)",
    "clogging": "cutting + chip evacuation (Eqs 3.16/3.19)",
    "chi": "Chi empirical thrust (Eq 2.24)",
    "peng": "Peng simplified (Eqs 2.20-2.21)",
}

#: Material densities [g/cm³] of Table 3-1, used by Chi's density-based thrust.
CORTICAL_DENSITY_G_CM3 = 1.70
CANCELLOUS_DENSITY_G_CM3 = 0.32
#: Cortical ultimate tensile strength [MPa], Table 2-4 (longitudinal), Peng's R_a.
CORTICAL_TENSILE_STRENGTH_MPA = 133.0
CANCELLOUS_STRENGTH_MPA = 7.56


@dataclass(frozen=True)
class DrillingConditions:
    """Operating point of one hole: feed, speed, cortex thickness, drill and bone set.

    ``friction`` (μ_f, μ_w), when given, replaces the bone set's power law.
    """

    feed_mm_s: float
    spindle_rpm: float
    cortex_mm: float = 6.0
    bone: BoneSet = field(default_factory=lambda: builtin_bone_set("bovine"))
    drill: Drill = Drill()
    friction_override: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        feed_per_revolution(self.feed_mm_s, self.spindle_rpm)  # validates f and N
        require(np.isfinite(self.cortex_mm) and self.cortex_mm > 0,
                f"cortical thickness must be a positive length in mm, got {self.cortex_mm}")
        if self.friction_override is not None:
            require(all(np.isfinite(m) and m > 0 for m in self.friction_override),
                    f"friction coefficients must be positive, got {self.friction_override}")

    @property
    def feed_per_rev_mm(self) -> float:
        """a = f·60/N [mm/rev]."""
        return feed_per_revolution(self.feed_mm_s, self.spindle_rpm)

    @property
    def friction(self) -> tuple[float, float]:
        """(μ_f, μ_w): the override if given, else the bone set's power law at (f, N)."""
        if self.friction_override is not None:
            return self.friction_override
        return self.bone.friction(self.feed_mm_s, self.spindle_rpm)

    @property
    def growth_exponent(self) -> float:
        """p = ηMD/S of the chip-evacuation model at (f, N)."""
        return clogging.growth_exponent(*self.friction, self.drill)

    def phase_times(self) -> dict[str, float]:
        """Times [s] of contact, full engagement, breakthrough and full cancellous engagement."""
        l, h, f = self.drill.cone_length_mm, self.cortex_mm, self.feed_mm_s
        return {"contact": 0.0, "full engagement": min(l, h) / f,
                "breakthrough": h / f, "fully in cancellous": (h + l) / f}

    def static_allotta(self) -> tuple[float, float]:
        """Full-engagement Allotta thrust [N] and torque [N·mm]: the static comparison load."""
        return allotta.full_engagement(self.feed_per_rev_mm, self.bone.u1_MPa, self.drill)


@dataclass(frozen=True)
class LoadHistory:
    """Thrust [N] and torque [N·mm] (NaN where a model has none) against time [s] and depth [mm]."""

    model: str
    time_s: np.ndarray
    depth_mm: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray


def evaluate(model: str, cond: DrillingConditions, time_s) -> LoadHistory:
    """Evaluate one load model at the given times [s] after contact (vectorised)."""
    require(model in MODELS, f"unknown load model '{model}': choose one of {', '.join(MODELS)}")
    t = np.asarray(time_s, dtype=float)
    d = np.maximum(cond.feed_mm_s * t, 0.0)
    a, h, drill, bone = cond.feed_per_rev_mm, cond.cortex_mm, cond.drill, cond.bone
    in_cortex = (d > 0) & (d <= h)
    in_cancellous = d > h
    if model in ("allotta", "clogging"):
        F = allotta.thrust(d, a, h, bone.u1_MPa, bone.u2_MPa, drill)
        T = allotta.torque(d, a, h, bone.u1_MPa, bone.u2_MPa, drill)
        if model == "clogging":
            F0, _ = cond.static_allotta()
            mu_f, mu_w = cond.friction
            l = drill.cone_length_mm
            z = np.maximum((np.minimum(d, h) - l) / drill.diameter_mm, 0.0)
            cone_in_cortex = np.clip(np.minimum(d, h) - np.maximum(d - l, 0.0), 0.0, l) / l
            F = F + (clogging.thrust(z, F0, mu_f, mu_w, drill) - F0) * cone_in_cortex
            T = T + clogging.torque(z, F0, mu_f, mu_w, drill) * cone_in_cortex
    elif model == "chi":
        F = (in_cortex * literature.chi_thrust(cond.feed_mm_s, cond.spindle_rpm, CORTICAL_DENSITY_G_CM3)
             + in_cancellous * literature.chi_thrust(cond.feed_mm_s, cond.spindle_rpm,
                                                     CANCELLOUS_DENSITY_G_CM3))
        T = np.full_like(d, np.nan)
    else:  # peng
        F = (in_cortex * literature.peng_thrust(a, bone.u1_MPa, drill)
             + in_cancellous * literature.peng_thrust(a, bone.u2_MPa, drill))
        T = (in_cortex * literature.peng_torque(a, CORTICAL_TENSILE_STRENGTH_MPA, drill)
             + in_cancellous * literature.peng_torque(a, CANCELLOUS_STRENGTH_MPA, drill))
    return LoadHistory(model, t, d, np.asarray(F, float), np.asarray(T, float))


def time_grid(cond: DrillingConditions, dt_s: float, end_s: float | None = None) -> np.ndarray:
    """Times 0, dt, … up to ``end_s`` (default: the tip fully in cancellous bone) [s]."""
    require(np.isfinite(dt_s) and dt_s > 0, f"time step must be positive in s, got {dt_s}")
    end = cond.phase_times()["fully in cancellous"] if end_s is None else end_s
    require(dt_s <= end, f"time step {dt_s} s is larger than the span {end:.4g} s")
    n = int(np.floor(end / dt_s + 1e-9))
    return np.append(np.arange(n + 1) * dt_s, [end] if n * dt_s < end - 1e-12 else [])
