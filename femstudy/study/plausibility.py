"""Physical plausibility gates: a study whose inputs or results cannot describe a femur being
drilled stops with one line, or, with ``force``, runs on and is marked out of range.

Four gates, each as early as what it checks is known:

- before any work (:func:`input_findings`): a friction coefficient that the bone set's power
  law (thesis Eq 4.5) gives at an operating point outside the conditions it was calibrated
  on, when that value lies beyond half the smallest to twice the largest calibrated value.
  The human law is steep: at 3 mm/s and 1500 rpm it gives μ_w = 43 (calibrated 0.52–2.4),
  at 1.5 mm/s 0.03; the bovine law stays within its range far outside its box, and passes.
- as soon as the loads are known (:func:`load_findings`; before any work when the depth is
  given): a thrust beyond 10 kN or a torque beyond 100 N·m, the bounds of a drilling
  recording (:mod:`femstudy.recordings.ranges`), or loads that are not finite numbers.
- after meshing (:func:`site_findings`): a drilled depth deeper than the bone along the drill
  axis at the site (plus the drill's tip cone): the load model would cut bone that is not
  there.
- after solving (:func:`result_findings`): any deflection beyond
  :data:`DEFLECTION_SHARE` of the bone's length (the solver's small-displacement theory no
  longer holds there: rotations of several per cent), any stress beyond
  :data:`STRESS_FACTOR` times cortical bone's largest ultimate strength (205 MPa,
  thesis Table 2-4) or a strength ratio below 1 / :data:`STRESS_FACTOR`, and any deflection
  or stress that is not a finite number.

Each gate returns :class:`Finding` records; :func:`enforce` raises the first as a
:class:`~femstudy.errors.UserError` unless ``force``, in which case each is logged as a
warning and returned for summary.json's ``out_of_range`` list and report.md's banner.
docs/checks.md lists the thresholds.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femstudy import thesis
from femstudy.errors import UserError
from femstudy.meshing.ray_cells import cells_along

log = logging.getLogger(__name__)

#: A power-law friction value may lie this factor beyond its calibrated values' range.
FRICTION_FACTOR = 2.0
#: Largest deflection accepted, as a share of the bone's length.
DEFLECTION_SHARE = 0.02
#: Stresses are accepted up to this factor times :data:`BONE_STRENGTH_MPA`.
STRESS_FACTOR = 10.0
#: Cortical bone's largest ultimate strength [MPa] (longitudinal compression, Table 2-4).
BONE_STRENGTH_MPA = max(thesis.CORTICAL_STRENGTH_MPA.values())

_DEFLECTIONS = ("max_deflection_mm", "drill_point_deflection_mm", "resolved_peak_mm", "quasi_static_peak_mm",
                "resolved_drill_point_mm", "quasi_static_drill_point_mm")
_WORDS = {"max_deflection_mm": "maximum deflection", "drill_point_deflection_mm": "drill-point deflection",
          "resolved_peak_mm": "resolved transient's peak deflection",
          "quasi_static_peak_mm": "quasi-static peak deflection",
          "resolved_drill_point_mm": "resolved transient's drill-point deflection",
          "quasi_static_drill_point_mm": "quasi-static drill-point deflection"}


@dataclass(frozen=True)
class Finding:
    """One failed gate: which check, and the sentence that says why."""

    check: str
    message: str

    def as_dict(self) -> dict:
        return {"check": self.check, "message": self.message}


def friction_findings(drilling, bone_set) -> list[Finding]:
    """The power law's (μ_f, μ_w) at the case's (feed, speed), where it extrapolates beyond
    :data:`FRICTION_FACTOR` of its calibrated values (coefficients the case gives are not
    checked here: the schema bounds them)."""
    f, n = float(drilling.feed_mm_s), float(drilling.spindle_rpm)
    if bone_set.in_calibrated_range(f, n):
        return []
    findings = []  # (how far beyond, finding): the worse coefficient first
    for name, given, value, calibrated in zip(("mu_f", "mu_w"), (drilling.mu_f, drilling.mu_w),
                                              bone_set.friction(f, n), (bone_set.mu_f, bone_set.mu_w)):
        low, high = min(calibrated) / FRICTION_FACTOR, max(calibrated) * FRICTION_FACTOR
        if given is not None or (math.isfinite(value) and low <= value <= high):
            continue
        beyond = max(value / high, low / value) if math.isfinite(value) and value > 0 else math.inf
        findings.append((beyond, Finding("friction extrapolated", (
            f"drilling.feed_mm_s = {f:g} mm/s at spindle_rpm = {n:g} lies outside the conditions bone set "
            f"'{bone_set.name}' was calibrated on ({min(bone_set.feed_mm_s):g}-{max(bone_set.feed_mm_s):g} mm/s, "
            f"{min(bone_set.spindle_rpm):g}-{max(bone_set.spindle_rpm):g} rpm), and its power law gives {name} = "
            f"{value:.3g} there, beyond {low:.3g}-{high:.3g} (half the smallest to twice the largest calibrated "
            f"value); give drilling.{name}, or a bone set calibrated there"))))
    return [finding for _, finding in sorted(findings, key=lambda pair: -pair[0])]


def input_findings(case, bones_dir: Path | None = None) -> list[Finding]:
    """What can be judged before any work: the friction law's extrapolation."""
    from femstudy.drilling import load_bone_set

    return friction_findings(case.drilling, load_bone_set(case.drilling.bone, bones_dir))


def load_findings(loading) -> list[Finding]:
    """The drilling loads of a case (:class:`femstudy.study.loading.CaseLoading`) against
    what a drill can push and turn (:data:`femstudy.recordings.ranges.MAX_MAGNITUDE`:
    10 kN, 100 N·m, the bounds of a drilling recording)."""
    from femstudy.recordings.ranges import MAX_MAGNITUDE

    findings = []
    for what, unit, limit, values in (
            ("thrust", "N", MAX_MAGNITUDE["thrust"], [loading.dynamic.thrust_N, loading.static_thrust_N]),
            ("torque", "N·mm", MAX_MAGNITUDE["torque"], [loading.dynamic.torque_Nmm, loading.static_torque_Nmm])):
        values = np.concatenate([np.ravel(v) for v in values])
        peak = float(np.max(np.abs(values))) if values.size else 0.0
        if not np.all(np.isfinite(values)):
            findings.append(Finding("not a number", f"the drilling {what} is not a finite number: the load model "
                                                    "overflowed"))
        elif peak > limit:
            findings.append(Finding("load beyond a drill's", (
                f"the drilling {what} reaches {peak:.3g} {unit}, beyond the {limit:g} {unit} any drill in bone "
                f"exerts (friction mu_f = {loading.conditions.friction[0]:.3g}, mu_w = "
                f"{loading.conditions.friction[1]:.3g}, load_scale and the feed set it)")))
    return findings


def bone_along_axis_mm(mesh, entry, direction, max_mm: float, step_mm: float = 0.05) -> float:
    """Length of the first stretch of bone (tets of any region) along the ray from ``entry``
    in ``direction`` [mm], sampled every ``step_mm`` up to ``max_mm``."""
    s = np.arange(step_mm / 2, max_mm, step_mm)
    inside = cells_along(mesh, entry, direction, s) >= 0
    first = int(np.argmax(inside))  # the entry lies on the surface: skip samples that round outside
    if not inside[first]:
        return 0.0
    after = np.nonzero(~inside[first:])[0]
    return float(s[first + after[0]] - step_mm / 2) if len(after) else float(max_mm)


def site_findings(case, model) -> list[Finding]:
    """The drilled depth against the bone along the drill axis at the site."""
    from femstudy.drilling import Drill

    if case.drilling.depth_mm == "cortex":
        return []
    depth, site = float(case.drilling.depth_mm), model.site
    cone = Drill(diameter_mm=case.drill.diameter_mm, point_angle_deg=case.drill.point_angle_deg).cone_length_mm
    if depth <= site.cortical_thickness_mm + cone:
        return []
    bone = bone_along_axis_mm(model.mesh, site.entry_point, site.direction, depth + cone + 1.0)
    if depth <= bone + cone:
        return []
    return [Finding("depth beyond the bone", (
        f"drilling.depth_mm = {depth:g} mm, but along the drill axis at site '{case.site.name}' the bone is "
        f"{bone:.3g} mm deep (cortex {site.cortical_thickness_mm:.3g} mm) before the drill leaves it, so the load "
        f"model would cut bone that is not there; drill at most {bone + cone:.3g} mm (the bone and the drill's "
        f"{cone:.2g} mm tip cone), or depth_mm = \"cortex\""))]


def numbers_in(node, path=()):
    """(path, value) of every number in a nested summary document."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from numbers_in(value, path + (str(key),))
    elif isinstance(node, (list, tuple)):
        for k, value in enumerate(node):
            yield from numbers_in(value, path + (str(k),))
    elif isinstance(node, (int, float, np.floating, np.integer)) and not isinstance(node, bool):
        yield path, float(node)


def result_findings(summary: dict, length_mm: float) -> list[Finding]:
    """Deflections, stresses and strength ratios of a study's summary against the bounds of
    the module docstring (``length_mm``: the bone's length); the worst value of each check."""
    limit_mm, limit_MPa = DEFLECTION_SHARE * length_mm, STRESS_FACTOR * BONE_STRENGTH_MPA
    worst: dict[str, tuple[float, str]] = {}  # check -> (how far beyond, message)

    def beyond(check: str, severity: float, message: str) -> None:
        if check not in worst or severity > worst[check][0]:
            worst[check] = (severity, message)

    for part in ("results", "dynamics", "hole", "margins"):
        for path, value in numbers_in(summary.get(part) or {}):
            deflection = next((key for key in _DEFLECTIONS if key in path), None)
            where = " ".join(p for p in path if not p.isdigit() and p not in ("value", deflection)).replace("_", " ")
            stress = any("von_mises" in p or p.endswith("stress_MPa") for p in path)
            if path[-1] == "strength_ratio":
                if math.isnan(value):
                    beyond("not a number", math.inf, f"{where} is not a number: the solution failed")
                elif value < 1 / STRESS_FACTOR:  # inf, where a region is unloaded, is fine
                    beyond("stress beyond bone strength", 1 / max(value, 1e-300), (
                        f"{where} {value:.3g}: the stresses exceed bone's strength "
                        f"{1 / value if value > 0 else math.inf:.3g} times"))
            elif path[-1] == "value" or path[-1] in _DEFLECTIONS or (stress and path[-1].endswith("_MPa")):
                if not math.isfinite(value):
                    beyond("not a number", math.inf, f"{where} is {value}: the solution failed")
                elif deflection and abs(value) > limit_mm:
                    beyond("deflection beyond the bone", abs(value) / limit_mm, (
                        f"{_WORDS[deflection]} {value:.3g} mm{f' ({where})' if where else ''} is beyond "
                        f"{100 * DEFLECTION_SHARE:g} % of the "
                        f"{length_mm:.0f} mm bone ({limit_mm:.3g} mm), where the small-displacement model no longer "
                        "holds"))
                elif stress and abs(value) > limit_MPa:
                    beyond("stress beyond bone strength", abs(value) / limit_MPa, (
                        f"{where.replace(' MPa', '').replace('von mises', 'von Mises')} {value:.3g} MPa is more than {STRESS_FACTOR:g} times bone's ultimate strength "
                        f"({BONE_STRENGTH_MPA:g} MPa)"))
    return [Finding(check, message) for check, (_, message) in worst.items()]


def enforce(findings: list[Finding], force: bool, advice: str = "", forceable: bool = True) -> list[dict]:
    """Raise the first finding as a :class:`UserError` unless ``force``; with ``force`` log
    each as a warning and return them as records for summary.json. ``forceable``: the
    message offers ``--force`` (a sweep has none)."""
    if not findings:
        return []
    if not force:
        more = f" (and {len(findings) - 1} more out-of-range value{'s' * (len(findings) > 2)})" \
            if len(findings) > 1 else ""
        offer = "; --force runs it anyway and marks the results out of range" if forceable else ""
        raise UserError(f"{findings[0].message}{more}{f'; {advice}' if advice else ''}{offer}")
    for finding in findings:
        if finding not in _warned:  # a run of several cases judges each case's inputs twice
            _warned.add(finding)
            log.warning("out of range (--force): %s", finding.message)
    return [f.as_dict() for f in findings]


_warned: set[Finding] = set()


def check_inputs(case, bones_dir: Path | None, force: bool, forceable: bool = True) -> list[dict]:
    """:func:`input_findings` enforced (see :func:`enforce`)."""
    return enforce(input_findings(case, bones_dir), force, forceable=forceable)


def check_loads(loading, force: bool, forceable: bool = True) -> list[dict]:
    """:func:`load_findings` enforced."""
    return enforce(load_findings(loading), force, forceable=forceable)


def check_site(case, model, force: bool) -> list[dict]:
    """:func:`site_findings` enforced."""
    return enforce(site_findings(case, model), force)


def check_results(summary: dict, length_mm: float, force: bool) -> list[dict]:
    """:func:`result_findings` enforced, with advice on what drives a result out of range."""
    return enforce(result_findings(summary, length_mm), force,
                   "the inputs drive the bone beyond what the model describes: check the loads (drilling feed, speed, "
                   "friction, load_scale) and the materials")
