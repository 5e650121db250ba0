"""Load histories of a study case: the dynamic (cutting + chip evacuation) and the static
Allotta loading, sampled on the case's time grid (thesis §5.9), and the resolved history.

Dynamic: the case's load model (``drilling.model``, "clogging" by default: cutting + chip
evacuation; :mod:`femstudy.drilling.registry`) at its feed, speed, drill and bone set, through
the bone the drill crosses at the site: the cortex as thick as it is along the drill axis
(:class:`femstudy.femur_mesh.DrillSite`), then cancellous bone (cut at the bone set's u2) or the
canal (nothing to cut), whatever the drilled depth (thesis §2.2). Static: Allotta's
full-engagement thrust and torque, constant in time (the thesis's comparison load).
Resolved: the dynamic loading with its per-flute oscillation and breakthrough release, on a
grid that resolves both (:func:`resolved_loading`). Units: s, N, N·mm.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from femstudy.casefile import Case
from femstudy.drilling import (Drill, DrillingConditions, DynamicContent, LoadHistory, evaluate, load_bone_set,
                               load_parts, registry, time_grid)
from femstudy.hole.study import HoleInputs, StationLoad


@dataclass(frozen=True)
class CaseLoading:
    """Both loadings on one time grid, and what they were computed from.

    conditions : the operating point (feed, speed, drilled depth as the cortex, bone set, drill)
    model : the dynamic loading's load model (:mod:`femstudy.drilling.registry`)
    depth_mm : the drilled depth [mm]
    scale : ``drilling.load_scale``, already applied to every load here
    dynamic : the dynamic loading on the case's time grid
    static_thrust_N, static_torque_Nmm : Allotta's full-engagement load
    """

    conditions: DrillingConditions
    depth_mm: float
    dynamic: LoadHistory
    static_thrust_N: float
    static_torque_Nmm: float
    model: str = "clogging"
    scale: float = 1.0

    @property
    def times_s(self) -> np.ndarray:
        return self.dynamic.time_s

    def static(self) -> LoadHistory:
        """The static Allotta load as a (constant) history on the same grid."""
        t = self.times_s
        return LoadHistory("static allotta", t, self.dynamic.depth_mm,
                           np.full_like(t, self.static_thrust_N), np.full_like(t, self.static_torque_Nmm))

    @property
    def title(self) -> str:
        """The dynamic loading's load model, as its legend reads."""
        return registry.get(self.model).title

    def station(self, tip_depth_mm: float) -> StationLoad:
        """The dynamic loading's cutting and chip-evacuation parts when the tip is at
        ``tip_depth_mm`` (time = depth / feed), scaled like the loading."""
        t = tip_depth_mm / self.conditions.feed_mm_s
        parts = load_parts(self.model, self.conditions, np.array([t]))
        k = self.scale
        return StationLoad(t, k * float(parts.cutting_thrust_N[0]), k * float(parts.cutting_torque_Nmm[0]),
                           k * float(parts.evacuation_thrust_N[0]), k * float(parts.evacuation_torque_Nmm[0]))

    def hole_inputs(self, materials, order: int, clamp_length_mm: float) -> HoleInputs:
        """The hole models' inputs (:class:`femstudy.hole.study.HoleInputs`) for this loading."""
        return HoleInputs(self.conditions.drill, materials, order, clamp_length_mm, self.depth_mm, self.station,
                          (float(self.static_thrust_N), float(self.static_torque_Nmm)),
                          self.conditions.growth_exponent)


def drilled_depth_mm(case: Case, cortical_thickness_mm: float) -> float:
    """The drilled depth [mm]: the case's fixed depth, or through the local cortex along the
    drill axis ("cortex": to breakthrough)."""
    return cortical_thickness_mm if case.drilling.depth_mm == "cortex" else float(case.drilling.depth_mm)


def case_loading(case: Case, cortical_thickness_mm: float, bones_dir: Path | None = None,
                 beyond_cortex: str = "cancellous") -> CaseLoading:
    """Evaluate both loadings of ``case`` on its time grid (0 … end_s in step_s) for a cortex
    ``cortical_thickness_mm`` thick along the drill axis with ``beyond_cortex`` past it
    ("cancellous" or "canal"; both from the femur's :class:`~femstudy.femur_mesh.DrillSite`);
    calibrated bone sets are looked up in ``bones_dir``."""
    drill = Drill(diameter_mm=case.drill.diameter_mm, point_angle_deg=case.drill.point_angle_deg)
    if case.drill.wall_mm is not None:
        drill = drill.with_(wall_mm=case.drill.wall_mm)
    depth = drilled_depth_mm(case, cortical_thickness_mm)
    bone = load_bone_set(case.drilling.bone, bones_dir)
    friction = None
    if case.drilling.mu_f is not None or case.drilling.mu_w is not None:
        from_law = bone.friction(case.drilling.feed_mm_s, case.drilling.spindle_rpm)
        friction = (case.drilling.mu_f or from_law[0], case.drilling.mu_w or from_law[1])
    cond = DrillingConditions(case.drilling.feed_mm_s, case.drilling.spindle_rpm, cortical_thickness_mm, bone, drill,
                              friction, beyond_cortex)
    times = time_grid(cond, case.time.step_s, end_s=case.time.end_s)
    thrust, torque = cond.static_allotta()
    k = case.drilling.load_scale
    dynamic = evaluate(case.drilling.model, cond, times)
    dynamic = replace(dynamic, thrust_N=k * dynamic.thrust_N, torque_Nmm=k * dynamic.torque_Nmm)
    return CaseLoading(cond, depth, dynamic, k * thrust, k * torque, case.drilling.model, k)


def dynamic_content(case: Case, cond: DrillingConditions) -> DynamicContent:
    """The case's per-flute oscillation and breakthrough release ("flute": one flute passage)."""
    release = case.drilling.breakthrough_release_s
    if release == "flute":
        release = 1.0 / cond.drill.flute_passing_hz(cond.spindle_rpm)
    return DynamicContent(case.drilling.flute_oscillation, float(release))


def resolved_loading(case: Case, loading: CaseLoading, dt_s: float) -> LoadHistory:
    """The dynamic loading with its oscillation and release, every ``dt_s`` [s] over the
    resolved window: from ``analysis.resolved_lead_s`` before breakthrough (or contact) to
    0.1 s past the release."""
    cond = loading.conditions
    content = dynamic_content(case, cond)
    breakthrough = cond.phase_times()["breakthrough"]
    start = max(0.0, breakthrough - case.analysis.resolved_lead_s)
    end = breakthrough + content.release_s + 0.1
    times = start + np.arange(int(np.floor((end - start) / dt_s + 1e-9)) + 1) * dt_s
    history = evaluate(loading.model, cond, times, content)
    k = loading.scale
    return replace(history, thrust_N=k * history.thrust_N, torque_Nmm=k * history.torque_Nmm)
