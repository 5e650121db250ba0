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
alike. A choice whose alternative cannot be computed (a local model that no longer fits the
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
    overrides: dict
    hole: dict
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

    values: dict

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
    changes: dict
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
    uncertainty_percent: dict
    station: int
    seconds: float

    def to_json(self) -> dict:
        return {"baseline": self.baseline.values, "station": self.station, "seconds": self.seconds,
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


def at_station(result, station: int):
    """The HoleResult restricted to one station's measures."""
    return replace(result, measures=tuple(m for m in result.measures if m.station == station),
                   stations=tuple(s for s in result.stations if s.station == station))


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
    """One choice's alternative computed: its answers, what it cost [s], and why it could not be
    computed (``failed``: the alternative's model is refused, e.g. a local model that no longer
    fits the bone; its answers are then NaN)."""

    choice: Choice
    answers: Answers
    seconds: float
    failed: str = ""


def run_variants(case, model, loading, unit_fields: np.ndarray, solver: str, keep, cache_dir, hole: bool,
                 modes: bool) -> tuple:
    """Every choice's alternative for ``case`` (its GlobalModel ``model``, CaseLoading
    ``loading`` and the baseline's global field per unit patch thrust and torque,
    ``unit_fields``): the deflections, the lowest frequency when ``modes``, and the near-hole
    answers at the deepest station when ``hole`` (module docstring). Returns the baseline's
    near-hole answers (computed like the alternatives') and one :class:`Variant` per choice."""
    from femstudy import fe
    from femstudy.casefile import with_overrides
    from femstudy.study.global_model import prepare
    from femstudy.errors import UserError
    from femstudy.study.verification import analyse_hole

    amplitudes = np.column_stack([loading.dynamic.thrust_N, loading.dynamic.torque_Nmm])
    options = case.loads.hole_options()

    def hole_values(variant_model, fields, hole_options) -> dict:
        inputs = loading.hole_inputs(variant_model.case.materials.to_fe(), case.mesh.order,
                                     variant_model.case.clamps.length_mm)
        result = analyse_hole(inputs, variant_model.femur, variant_model.system, fields, hole_options, solver, keep,
                              verified=False, stations=(-1,)).result
        return hole_answers(result, hole_options)

    def _alternative(choice) -> dict:
        """The answers of one choice's alternative."""
        values = {}
        variant_model, fields = model, unit_fields
        if choice.global_model:
            variant = with_overrides(case, choice.overrides, what="sensitivity")
            variant_model = model.clamped(variant) if set(choice.overrides) == {"clamps.length_mm"} else \
                prepare(variant, cache_dir)  # the clamps change no stiffness: the system is the baseline's
            fs = variant_model.factorize(solver, keep)
            values.update(quasi_static_peaks(fs, variant_model.patch, variant_model.channels, amplitudes))
            if modes:
                values["f1_Hz"] = float(fe.solve_modal(fs, k=1).frequency_Hz[0])
            fields = fs.bc.expand(fs.factor.solve(variant_model.patch.patterns[fs.bc.free]))
            fs.factor.close()
        if hole:
            values.update(hole_values(variant_model, fields, replace(options, **choice.hole)))
        return values

    baseline_hole = hole_values(model, unit_fields, options) if hole else {}
    out = []
    for choice in choices(case):
        began = time.perf_counter()
        try:
            values = _alternative(choice)
        except UserError as exc:
            log.warning("sensitivity: %s %s could not be computed: %s", choice.name, choice.setting, exc)
            out.append(Variant(choice, Answers({}), time.perf_counter() - began, str(exc)))
            continue
        out.append(Variant(choice, Answers(values), time.perf_counter() - began))
        log.info("sensitivity: %s %s, %.1f s", choice.name, choice.setting, out[-1].seconds)
    return baseline_hole, tuple(out)


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


def sensitivity_table(variants: tuple, baseline: Answers, uncertainty_percent: dict, station: int) -> Sensitivity:
    """The table of ``variants`` (:func:`run_variants`) against the ``baseline``; an answer a
    variant did not compute (the deflections of a hole-model choice) did not change."""
    rows = []
    for v in variants:
        if v.failed:
            rows.append(Row(v.choice, dict.fromkeys(baseline.values, math.nan), v.seconds, v.failed))
            continue
        values = {**baseline.values, **v.answers.values}
        changes = Answers(values).change(baseline)
        rows.append(Row(v.choice, {k: (x if k in v.answers.values else None) for k, x in changes.items()},
                        v.seconds))
    return Sensitivity(baseline, tuple(rows), uncertainty_percent, station, sum(v.seconds for v in variants))
