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

from femstudy import thesis
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

#: Peng's material strength R_a [MPa]: Table 2-4's longitudinal tensile strength for the
#: cortex and Table 2-5's mean for cancellous bone.
CORTICAL_TENSILE_STRENGTH_MPA = thesis.CORTICAL_STRENGTH_MPA["longitudinal_tension_ultimate"]
CANCELLOUS_STRENGTH_MPA = thesis.CANCELLOUS_STRENGTH_MPA["mean"]


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
class DynamicContent:
    """What a resolved transient adds to the loads' slow growth (docs/load-models.md).

    flute_oscillation : relative amplitude A of the per-flute oscillation: thrust and torque
                        times (1 + A sin 2π f_fp t), f_fp = flutes · N/60 (50 Hz at 1500 rpm)
    release_s         : the chip-evacuation load released at breakthrough linearly over this
                        time [s] (the chips escape through the exit hole) instead of fading with
                        the cone's share of cortex; None keeps the fade
    """

    flute_oscillation: float = 0.0
    release_s: float | None = None

    def __post_init__(self) -> None:
        require(0 <= self.flute_oscillation < 1, f"flute oscillation amplitude must lie in [0, 1), "
                                                 f"got {self.flute_oscillation}")
        require(self.release_s is None or self.release_s > 0, f"release time must be positive, got {self.release_s}")


@dataclass(frozen=True)
class LoadHistory:
    """Thrust [N] and torque [N·mm] (NaN where a model has none) against time [s] and depth [mm]."""

    model: str
    time_s: np.ndarray
    depth_mm: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray


def evaluate(model: str, cond: DrillingConditions, time_s, content: DynamicContent = DynamicContent()) -> LoadHistory:
    """Evaluate one load model at the given times [s] after contact (vectorised); ``content``
    adds the per-flute oscillation and the breakthrough release (model "clogging" only)."""
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
            if content.release_s is not None:  # released within release_s of breakthrough (t = h/f)
                cone_in_cortex = np.clip(1 - (t - h / cond.feed_mm_s) / content.release_s, 0.0, 1.0) * (d > 0)
            F = F + (clogging.thrust(z, F0, mu_f, mu_w, drill) - F0) * cone_in_cortex
            T = T + clogging.torque(z, F0, mu_f, mu_w, drill) * cone_in_cortex
            if content.flute_oscillation:
                wave = 1 + content.flute_oscillation * np.sin(2 * np.pi * drill.flute_passing_hz(cond.spindle_rpm) * t)
                F, T = F * wave, T * wave
    elif model == "chi":
        F = (in_cortex * literature.chi_thrust(cond.feed_mm_s, cond.spindle_rpm, thesis.CORTICAL_DENSITY_G_CM3)
             + in_cancellous * literature.chi_thrust(cond.feed_mm_s, cond.spindle_rpm,
                                                     thesis.CANCELLOUS_DENSITY_G_CM3))
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
