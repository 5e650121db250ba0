"""How much the study's modelling choices move its answers: a one-at-a-time sensitivity table.

Each choice a model of drilled bone has to make is changed alone, to a stated alternative,
and the study's answers are computed again: the largest deflection and the drill point's under
the dynamic loading (quasi-static: the loads change over seconds, far below the lowest mode),
the lowest natural frequency, the von Mises stress at each distance from the hole and beyond
the quoted exclusion radius, and the governing margin. Each change is a percentage of the
baseline, beside the verification's own uncertainty of the same answer, so a reader sees
whether the mesh or a modelling choice dominates (docs/study.md).

The choices (:data:`CHOICES`) and their alternatives:

- clamp length, 10 and 40 mm against 20 mm: how much of each end the (unmodelled) hip and knee
  hold rigidly;
- cut radius of the local hole models, 6 and 10 mm against 8 mm;
- ligament rule, the least bone left ahead of the deepest tip, 0.25 and 1 mm against 0.5 mm;
- cortex, transversely isotropic against isotropic (femstudy.fe.materials);
- cone traction, uniform against Allotta's constant force per unit lip length;
- cortical Young's modulus ±1 SD: ±22 %, the coefficient of variation of human femoral cortical
  bone's longitudinal modulus (17.9 ± 3.9 GPa, Reilly & Burstein 1975, J Biomech 8:393–405, the
  source of the thesis's Table 2-4).

Choices of the global model (clamps, cortex, modulus) need their own stiffness matrices,
factorised once and kept like the study's (:mod:`femstudy.fe.kept`: a repeated study factorises
none of them). The near-hole answers are compared at the deepest station, where the drill is
closest to breakthrough and the measures have their largest values, baseline and alternatives
alike; the alternatives that keep the local meshes are measured on the baseline's meshes and
points, one factorisation per material and two right-hand sides per global field (:func:`run_variants`).
A choice whose alternative cannot be computed (a local model that no longer fits the
bone) is reported as such. Units: mm, Hz, MPa, %.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

log = logging.getLogger(__name__)

#: Relative one-SD spread of the cortical Young's modulus (module docstring).
CORTICAL_MODULUS_SD = 0.22


@dataclass(frozen=True)
class Choice:
    """One modelling choice changed alone: ``name``, the alternative ``setting`` and the
    ``baseline`` in words, what it changes in the case (``overrides``, dotted keys) or in the
    hole models (``hole``: HoleOptions fields), and the reason for its range (``source``)."""

    name: str
    setting: str
    baseline: str
    overrides: dict[str, float | str]
    hole: dict[str, float | str]
    source: str

    @property
    def global_model(self) -> bool:
        return bool(self.overrides)


def choices(case) -> tuple[Choice, ...]:
    """The alternatives of every choice for ``case`` (module docstring)."""
    clamp = case.clamps.length_mm
    radius = case.loads.submodel_radius_mm
    ligament = case.loads.ligament_mm
    modulus = case.materials.cortical.youngs_modulus_GPa
    other_cortex = "transversely_isotropic" if case.materials.cortical_model == "isotropic" else "isotropic"
    other_cone = "uniform" if case.loads.cone_traction == "allotta" else "allotta"
    out = [Choice("clamp length", f"{f * clamp:g} mm", f"{clamp:g} mm", {"clamps.length_mm": f * clamp}, {},
                  "half and twice the clamped length: the hip and knee hold an unknown length rigidly")
           for f in (0.5, 2.0)]
    out += [Choice("cut radius", f"{r:g} mm", f"{radius:g} mm", {}, {"submodel_radius_mm": r},
                   "the local model's radius, where it takes the global displacements") for r in (radius - 2, radius + 2)]
    out += [Choice("ligament rule", f"{f * ligament:g} mm", f"{ligament:g} mm", {}, {"ligament_mm": f * ligament},
                   "the least bone left ahead of the deepest tip") for f in (0.5, 2.0)]
    out += [Choice("cortex", other_cortex.replace("_", " "), case.materials.cortical_model.replace("_", " "),
                   {"materials.cortical_model": other_cortex}, {}, "femstudy.fe.materials")]
    out += [Choice("cone traction", other_cone, case.loads.cone_traction, {}, {"cone_traction": other_cone},
                   "Allotta's constant force per unit lip length against a uniform traction")]
    out += [Choice("cortical modulus", f"{modulus * (1 + s):.3g} GPa", f"{modulus:g} GPa",
                   {"materials.cortical.youngs_modulus_GPa": modulus * (1 + s)}, {},
                   "±1 SD (22 %) of human femoral cortical bone, Reilly & Burstein 1975")
            for s in (-CORTICAL_MODULUS_SD, CORTICAL_MODULUS_SD)]
    return tuple(out)


@dataclass(frozen=True)
class Answers:
    """The answers the table compares (NaN where not computed)."""

    values: dict[str, float]

    def change(self, baseline: "Answers") -> dict:
        """Relative change of each answer against ``baseline`` [%]."""
        out = {}
        for key, value in self.values.items():
            base = baseline.values.get(key, math.nan)
            out[key] = 100.0 * (value - base) / abs(base) if base and math.isfinite(base) and math.isfinite(value) \
                else math.nan
        return out


@dataclass(frozen=True)
class Row:
    """One choice's alternative and how much it moved each answer [%] (``failed``: why it could not
    be computed)."""

    choice: Choice
    changes: dict[str, float]
    seconds: float
    failed: str = ""

    def as_dict(self) -> dict:
        c = self.choice
        return {"choice": c.name, "setting": c.setting, "baseline": c.baseline, "source": c.source,
                "changes_percent": self.changes, "seconds": self.seconds, "not_computed": self.failed or None}


@dataclass(frozen=True)
class Sensitivity:
    """The table: the baseline's answers, each choice's row, the verification's uncertainty of
    each answer [%] beside them, and the cost."""

    baseline: Answers
    rows: tuple
    uncertainty_percent: dict[str, float | None]
    station: int
    seconds: float
    kept: bool = False

    def to_json(self) -> dict:
        return {"baseline": self.baseline.values, "station": self.station, "seconds": self.seconds,
                "kept_from_earlier_run": self.kept,
                "mesh_uncertainty_percent": self.uncertainty_percent, "rows": [r.as_dict() for r in self.rows]}


def quasi_static_peaks(fs, patch, channels, amplitudes: np.ndarray) -> dict:
    """Largest deflection and drill-point deflection [mm] over the loading's steps, quasi-static:
    u(t) = K⁻¹P a(t) (``amplitudes``: (steps, 2) thrust [N] and torque [N·mm])."""
    from femstudy import fe

    shapes = fs.factor.solve(patch.patterns[fs.bc.free])
    Q, R = np.linalg.qr(shapes)
    chosen = [ch for ch in channels if ch.name in ("deflection", "drill_point")]
    history = fe.reduced_history(chosen, fs.bc.expand(Q), R @ amplitudes.T)
    return {"max_deflection_mm": float(history["deflection"].peak),
            "drill_point_deflection_mm": float(history["drill_point"].peak)}


def hole_answers(result, options) -> dict:
    """The near-hole answers of a HoleResult: the dynamic von Mises at each distance and beyond
    the quoted exclusion radius (largest over its stations) and the smallest margin."""
    out = {}
    for d in options.distances_mm:
        out[f"von_mises_{d:g}mm_MPa"] = max((m.von_mises_MPa for m in result.measures if m.kind == "distance"
                                            and m.loading == "dynamic" and abs(m.radius_mm - d) < 1e-9
                                            and np.isfinite(m.von_mises_MPa)), default=math.nan)
    rho = options.exclusion_radius_mm
    out[f"von_mises_beyond_{rho:g}mm_MPa"] = max((m.von_mises_MPa for m in result.measures
                                                  if m.kind == "exclusion" and m.loading == "dynamic"
                                                  and abs(m.radius_mm - rho) < 1e-9 and np.isfinite(m.von_mises_MPa)),
                                                 default=math.nan)
    margins = [min(m.strength_ratio, m.strain_ratio) for m in result.measures if m.loading == "dynamic"]
    margins = [x for x in margins if np.isfinite(x)]
    out["governing_margin"] = min(margins) if margins else math.nan
    return out


def baseline_answers(fs, model, loading, frequency_Hz: float | None) -> Answers:
    """The baseline's global answers, computed like the variants' (quasi-static deflections
    over the dynamic loading; the lowest frequency); :func:`with_hole` adds the near-hole ones."""
    amplitudes = np.column_stack([loading.dynamic.thrust_N, loading.dynamic.torque_Nmm])
    base = quasi_static_peaks(fs, model.patch, model.channels, amplitudes)
    base["f1_Hz"] = math.nan if frequency_Hz is None else float(frequency_Hz)
    return Answers(base)


def with_hole(answers: Answers, hole_values: dict | None) -> Answers:
    """``answers`` and the baseline's near-hole answers (:func:`run_variants`)."""
    return answers if not hole_values else Answers({**answers.values, **hole_values})


@dataclass(frozen=True)
class Variant:
    """One choice's alternative computed: its answers, what it cost on its own [s] (its global
    model, or its own hole model), and why it could not be computed (``failed``: the
    alternative's model is refused, e.g. a local model that no longer fits the bone; its answers
    are then NaN)."""

    choice: Choice
    answers: Answers
    seconds: float
    failed: str = ""


@dataclass(frozen=True)
class Variants:
    """Every choice's alternative (:func:`run_variants`): the baseline's near-hole answers,
    one :class:`Variant` per choice, and the wall time of the hole model the baseline and the
    alternatives that keep its meshes share [s]."""

    baseline_hole: dict[str, float]
    variants: tuple
    shared_seconds: float
    kept: bool = False

    def read_back(self) -> Variants:
        """These alternatives as read from an earlier run of the same inputs (femstudy.kept_answers)."""
        return replace(self, kept=True)


def _global_alternative(choice, case, model, amplitudes, solver, keep, cache_dir, modes: bool):
    """A global-model choice's deflections (and f1) and its unit fields (n_dofs, 2), with the
    materials of its local models (None: the case's)."""
    from femstudy import fe
    from femstudy.casefile import with_overrides
    from femstudy.study.global_model import prepare

    variant = with_overrides(case, choice.overrides, what="sensitivity")
    clamps_only = set(choice.overrides) == {"clamps.length_mm"}
    variant_model = model.clamped(variant) if clamps_only else prepare(variant, cache_dir)
    fs = variant_model.factorize(solver, keep)
    values = quasi_static_peaks(fs, variant_model.patch, variant_model.channels, amplitudes)
    if modes:
        values["f1_Hz"] = float(fe.solve_modal(fs, k=1).frequency_Hz[0])
    fields = fs.bc.expand(fs.factor.solve(variant_model.patch.patterns[fs.bc.free]))
    fs.factor.close()
    return values, fields, None if clamps_only else variant.materials.to_fe(), variant.clamps.length_mm


def run_variants(case, model, loading, unit_fields: np.ndarray, solver: str, keep, cache_dir, hole: bool,
                 modes: bool) -> Variants:
    """Every choice's alternative for ``case`` (its GlobalModel ``model``, CaseLoading
    ``loading`` and the baseline's global field per unit patch thrust and torque,
    ``unit_fields``): the deflections, the lowest frequency when ``modes``, and the near-hole
    answers at the deepest station when ``hole`` (module docstring).

    The alternatives that keep the local meshes (clamps, cortex, modulus, cone traction) are
    measured with the baseline in one call of :func:`femstudy.hole.study.hole_stresses`, as
    its :class:`~femstudy.hole.study.HoleScenario`: the meshes, the cut nodes' places and the
    measures' points are built once, a global alternative adds two right-hand sides (its unit
    fields on the cut faces) and a material one a factorisation. The ligament rule's
    alternatives reuse the site's surfaces with other stations; the cut radius's build theirs."""
    from femstudy.errors import UserError
    from femstudy.hole.probe import MeshLocator
    from femstudy.hole.study import HoleScenario, hole_site, hole_stresses

    amplitudes = np.column_stack([loading.dynamic.thrust_N, loading.dynamic.torque_Nmm])
    options = case.loads.hole_options()
    inputs = loading.hole_inputs(case.materials.to_fe(), case.mesh.order, case.clamps.length_mm)
    done, scenarios = {}, []
    for index, choice in enumerate(choices(case)):
        began = time.perf_counter()
        try:
            values = {}
            if choice.global_model:
                values, fields, materials, clamp = _global_alternative(choice, case, model, amplitudes, solver, keep,
                                                                       cache_dir, modes)
                if hole:
                    scenarios.append(HoleScenario(str(index), fields, materials, None, clamp))
            elif "cone_traction" in choice.hole:
                scenarios.append(HoleScenario(str(index), cone_traction=choice.hole["cone_traction"]))
        except UserError as exc:
            log.warning("sensitivity: %s %s could not be computed: %s", choice.name, choice.setting, exc)
            done[index] = Variant(choice, Answers({}), time.perf_counter() - began, str(exc))
            continue
        done[index] = Variant(choice, Answers(values), time.perf_counter() - began)
    baseline_hole, shared = {}, 0.0
    if hole:
        began = time.perf_counter()
        site, locator = hole_site(inputs, model.femur, options), MeshLocator(model.system)
        result = hole_stresses(inputs, model.femur, model.system, unit_fields, options, solver, keep, site=site,
                               stations=(-1,), scenarios=tuple(scenarios), locator=locator)
        baseline_hole = hole_answers(result, options)
        for scenario in scenarios:
            index = int(scenario.name)
            measured = hole_answers(replace(result, measures=result.scenarios[scenario.name]), options)
            v = done[index]
            done[index] = replace(v, answers=Answers({**v.answers.values, **measured}))
        shared = time.perf_counter() - began
        for index, choice in enumerate(choices(case)):
            if choice.global_model or "cone_traction" in choice.hole or done[index].failed:
                continue
            began = time.perf_counter()
            try:
                if set(choice.hole) == {"ligament_mm"}:
                    own = site.with_ligament(choice.hole["ligament_mm"], inputs.drilled_depth_mm)
                else:
                    own = hole_site(inputs, model.femur, replace(options, **choice.hole))
                found = hole_stresses(inputs, model.femur, model.system, unit_fields, options, solver, keep,
                                      site=own, stations=(-1,), locator=locator)
                done[index] = Variant(choice, Answers(hole_answers(found, own.options)), time.perf_counter() - began)
            except UserError as exc:
                log.warning("sensitivity: %s %s could not be computed: %s", choice.name, choice.setting, exc)
                done[index] = Variant(choice, Answers({}), time.perf_counter() - began, str(exc))
    for index, choice in enumerate(choices(case)):
        if not done[index].failed:
            log.info("sensitivity: %s %s, %.1f s", choice.name, choice.setting, done[index].seconds)
    log.info("sensitivity: the baseline and %d alternatives on the same local meshes, %.1f s", len(scenarios), shared)
    return Variants(baseline_hole, tuple(done[i] for i in range(len(done))), shared)


def uncertainties(analysis) -> dict:
    """The verification's relative uncertainty [%] of the near-hole answers (none for a run
    without verification): of the von Mises stress at each distance and beyond the quoted
    exclusion radius, and of the governing margin's measure."""
    if analysis is None or analysis.verification is None:
        return {}
    v, options = analysis.verification, analysis.result.options
    out = {}
    for d in options.distances_mm:
        found = v.of("distance", d)
        out[f"von_mises_{d:g}mm_MPa"] = None if found is None else 100 * found.uncertainty
    found = v.of("exclusion", options.exclusion_radius_mm)
    out[f"von_mises_beyond_{options.exclusion_radius_mm:g}mm_MPa"] = None if found is None else 100 * found.uncertainty
    margins = [x for x in v.verdicts if x.quantity == "margin" and x.loading == "dynamic" and np.isfinite(x.values[-1])]
    if margins:
        out["governing_margin"] = 100 * min(margins, key=lambda x: x.values[-1]).uncertainty
    return out


def sensitivity_table(variants: tuple, baseline: Answers, uncertainty_percent: dict, station: int,
                      shared_seconds: float = 0.0, kept: bool = False) -> Sensitivity:
    """The table of ``variants`` (:func:`run_variants`) against the ``baseline``; an answer a
    variant did not compute (the deflections of a hole-model choice) did not change. Its cost is
    the variants' own and the ``shared_seconds`` of the hole model they share (what computing
    them took, when they were ``kept`` from an earlier run)."""
    rows = []
    for v in variants:
        if v.failed:
            rows.append(Row(v.choice, dict.fromkeys(baseline.values, math.nan), v.seconds, v.failed))
            continue
        values = {**baseline.values, **v.answers.values}
        changes = Answers(values).change(baseline)
        rows.append(Row(v.choice, {k: (x if k in v.answers.values else None) for k, x in changes.items()},
                        v.seconds))
    return Sensitivity(baseline, tuple(rows), uncertainty_percent, station,
                       shared_seconds + sum(v.seconds for v in variants), kept)
