"""Thrust and torque histories of a unicortical hole for each load model.

The drill touches the bone at t = 0 and advances at the feed f, so the tip depth is
d = f·t [mm]. Phases: entry ramp 0 < d < l (tip cone entering the cortex), full engagement
l ≤ d ≤ h (cortex of thickness h), transition h < d < h + l (cone crossing into cancellous
bone), cancellous d ≥ h + l. "Breakthrough" is the instant the tip reaches the inner
surface of the cortex, d = h.

Each model is registered in :mod:`femstudy.drilling.registry` by its own module in
:mod:`femstudy.drilling.models` (Allotta's cutting, cutting + chip evacuation, Chi, Peng) and
gives its loads as a cutting and a chip-evacuation part; :func:`evaluate` adds them and the
per-flute oscillation. Units: s, mm, N, N·mm.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from femstudy.drilling import allotta, clogging, registry
from femstudy.drilling.drill import Drill, feed_per_revolution
from femstudy.drilling.friction import BoneSet, builtin_bone_set
from femstudy.drilling.registry import LoadParts
from femstudy.errors import require


@dataclass(frozen=True)
class DrillingConditions:
    """Operating point of one hole: feed, speed, cortex thickness, drill and bone set.

    ``friction`` (μ_f, μ_w), when given, replaces the bone set's power law. ``beyond_cortex``
    is what the drill meets once through the cortex: "cancellous" bone (cut at the bone set's
    u2) or the "canal" (no bone: nothing to cut, u2 = 0, thesis §2.2 and Allotta's model with
    the exit into air).
    """

    feed_mm_s: float
    spindle_rpm: float
    cortex_mm: float = 6.0
    bone: BoneSet = field(default_factory=lambda: builtin_bone_set("bovine"))
    drill: Drill = Drill()
    friction_override: tuple[float, float] | None = None
    beyond_cortex: str = "cancellous"

    def __post_init__(self) -> None:
        feed_per_revolution(self.feed_mm_s, self.spindle_rpm)  # validates f and N
        require(np.isfinite(self.cortex_mm) and self.cortex_mm > 0,
                f"cortical thickness must be a positive length in mm, got {self.cortex_mm}")
        if self.friction_override is not None:
            require(all(np.isfinite(m) and m > 0 for m in self.friction_override),
                    f"friction coefficients must be positive, got {self.friction_override}")
        require(self.beyond_cortex in ("cancellous", "canal"),
                f"beyond_cortex must be 'cancellous' or 'canal', got {self.beyond_cortex!r}")

    @property
    def u2_MPa(self) -> float:
        """The specific cutting energy beyond the cortex [MPa]: the bone set's cancellous u2, 0 in the canal."""
        return self.bone.u2_MPa if self.beyond_cortex == "cancellous" else 0.0

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


def load_parts(model: str, cond: DrillingConditions, time_s, content: DynamicContent = DynamicContent()) -> LoadParts:
    """The cutting and chip-evacuation parts of one registered load model at the given times [s]
    after contact (:mod:`femstudy.drilling.registry`), without the per-flute oscillation."""
    t = np.asarray(time_s, dtype=float)
    return registry.get(model).parts(cond, t, np.maximum(cond.feed_mm_s * t, 0.0), content)


def evaluate(model: str, cond: DrillingConditions, time_s, content: DynamicContent = DynamicContent()) -> LoadHistory:
    """Evaluate one registered load model at the given times [s] after contact (vectorised);
    ``content`` adds the per-flute oscillation (to the total) and the breakthrough release (to
    the chip-evacuation part)."""
    t = np.asarray(time_s, dtype=float)
    parts = load_parts(model, cond, t, content)
    F, T = parts.thrust_N, parts.torque_Nmm
    if content.flute_oscillation:
        wave = 1 + content.flute_oscillation * np.sin(2 * np.pi * cond.drill.flute_passing_hz(cond.spindle_rpm) * t)
        F, T = F * wave, T * wave
    return LoadHistory(model, t, np.maximum(cond.feed_mm_s * t, 0.0), np.asarray(F, float), np.asarray(T, float))


def time_grid(cond: DrillingConditions, dt_s: float, end_s: float | None = None) -> np.ndarray:
    """Times 0, dt, … up to ``end_s`` (default: the tip fully in cancellous bone) [s]."""
    require(np.isfinite(dt_s) and dt_s > 0, f"time step must be positive in s, got {dt_s}")
    end = cond.phase_times()["fully in cancellous"] if end_s is None else end_s
    require(dt_s <= end, f"time step {dt_s} s is larger than the span {end:.4g} s")
    n = int(np.floor(end / dt_s + 1e-9))
    return np.append(np.arange(n + 1) * dt_s, [end] if n * dt_s < end - 1e-12 else [])
