"""The calibration pipeline behind ``femstudy calibrate`` (thesis §4.1.4, §4.4, §5.1–5.5).

Recordings → processed cuts → per-run friction → outliers flagged per condition → friction
per condition from its replicates → power law (a :class:`~femstudy.drilling.friction.BoneSet`) →
validation R² on held-out runs → normality of F_o and p → the neural network's neuron study.

Held-out runs are the ``validation`` recordings when given (the thesis's Table 5-3 runs),
otherwise ``holdout`` replicates per condition, drawn with a fixed seed from the runs that
are not outliers (only where at least three would remain).

A condition's friction is the geometric mean of its runs' own estimates: the runs scatter
log-normally about it, and one least-squares fit to all replicates at once (the thesis's
way, kept as ``pooled`` for comparison) weighs the runs by the size of their loads, so the
runs that clog most dominate. Over 20 synthetic conditions (4 data sets, 10 replicates,
Appendix B's spread) the pooled fit erred by +2.7 % on average (rms 6.3 %) against the
runs' own mean friction, the geometric mean by −0.7 % (rms 4.2 %).
"""

from __future__ import annotations

import logging
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from femstudy.drilling import clogging
from femstudy.drilling.friction import CANCELLOUS_SPECIFIC_ENERGY_MPA, CORTICAL_SPECIFIC_ENERGY_MPA, BoneSet
from femstudy.errors import require
from femstudy.recordings import ann as ann_module
from femstudy.recordings.calibration import (FrictionFit, Validation, cortical_energy_MPa, fit_friction, fit_growth,
                                             outlier_reasons, power_law_set, r_squared, validate)
from femstudy.recordings.normality import NormalityResult, normality
from femstudy.recordings.processing import ProcessedRun

log = logging.getLogger(__name__)

TRUTH_KEYS = ("true_mu_f", "true_mu_w", "condition_mu_f", "condition_mu_w")


@dataclass
class RunResult:
    """One recording through the pipeline. ``role``: calibration, held out, validation or outlier."""

    run: ProcessedRun
    role: str
    fit: FrictionFit
    eq48_initial_force_N: float
    eq48_growth_exponent: float
    outlier_reason: str = ""
    validation: Validation | None = None
    ann_r2: tuple[float, float] | None = None

    @property
    def name(self) -> str:
        return self.run.name

    @property
    def condition(self) -> tuple[float, float]:
        return self.run.condition


@dataclass
class ConditionResult:
    """Friction of one (f, N) from its replicates, and the truth when headers carry it (synthetic data).

    ``mu_f``, ``mu_w`` are the geometric means of the used runs' own estimates, with standard
    errors of ln μ (sd/√n); ``pooled`` is the thesis-style single fit to all used runs at once,
    reported for comparison.
    """

    feed_mm_s: float
    spindle_rpm: float
    runs_used: list[str]
    per_run_mu_f: list[float]
    per_run_mu_w: list[float]
    pooled: FrictionFit
    true_mu_f: float | None = None
    true_mu_w: float | None = None

    @property
    def mu_f(self) -> float:
        return float(np.exp(np.mean(np.log(self.per_run_mu_f))))

    @property
    def mu_w(self) -> float:
        return float(np.exp(np.mean(np.log(self.per_run_mu_w))))

    def se_ln(self, values) -> float:
        """Standard error of the mean of ln μ over the runs (nan for one run)."""
        return float(np.std(np.log(values), ddof=1) / np.sqrt(len(values))) if len(values) > 1 else float("nan")

    @property
    def growth_exponent(self) -> float:
        return clogging.growth_exponent(self.mu_f, self.mu_w, self.pooled.drill)


@dataclass
class CalibrationResult:
    """The calibration of a bone set: every run's fit and role, each condition's friction,
    the power law (``bone``, a :class:`~femstudy.drilling.friction.BoneSet`), normality of
    F_o and p, and the neuron study; ``files`` lists what was written where, when anything was."""

    runs: list[RunResult]
    conditions: list[ConditionResult]
    bone: BoneSet
    u1_per_run_MPa: list[float]
    normality: dict[str, NormalityResult] = field(default_factory=dict)
    ann: ann_module.NeuronStudy | None = None
    notes: list[str] = field(default_factory=list)
    files: dict[str, Path | str] = field(default_factory=dict)

    def by_role(self, *roles: str) -> list[RunResult]:
        return [r for r in self.runs if r.role in roles]

    def table(self) -> list[dict]:
        """One row per condition: feed [mm/s], speed [rpm], runs used, μ_f and μ_w."""
        return [{"feed_mm_s": c.feed_mm_s, "spindle_rpm": c.spindle_rpm, "runs": len(c.runs_used),
                 "mu_f": c.mu_f, "mu_w": c.mu_w} for c in self.conditions]

    def to_json(self) -> dict:
        """Conditions, power-law coefficients, runs (name, role, μ_f, μ_w, outlier reason), files."""
        return {"bone_set": self.bone.name, "conditions": self.table(),
                "power_law": {"a": [float(x) for x in self.bone.a], "b": [float(x) for x in self.bone.b]},
                "runs": [{"run": r.name, "role": r.role, "mu_f": r.fit.mu_f, "mu_w": r.fit.mu_w,
                          "outlier_reason": r.outlier_reason} for r in self.runs],
                "files": {k: str(v) for k, v in self.files.items()}}


def _truth(runs: list[ProcessedRun], key: str) -> float | None:
    values = [r.metadata.get(key) for r in runs]
    return float(values[0]) if values and all(isinstance(v, (int, float)) and v == values[0] for v in values) \
        else None


def calibrate(calibration: list[ProcessedRun], validation: list[ProcessedRun] = (), name: str = "calibrated",
              holdout: int = 2, neurons: range | None = range(1, 11), seed: int = 0,
              ) -> CalibrationResult:
    """Run the whole calibration (see the module docstring) on processed runs."""
    require(len(calibration) > 0, "no calibration runs given")
    drill = calibration[0].drill
    for run in list(calibration) + list(validation):
        require(run.drill == drill, f"all runs must use one drill: {run.name} has D = {run.drill.diameter_mm} mm, "
                                    f"point angle {run.drill.point_angle_deg} deg; {calibration[0].name} has "
                                    f"D = {drill.diameter_mm} mm, {drill.point_angle_deg} deg")
    groups: dict[tuple[float, float], list[ProcessedRun]] = defaultdict(list)
    for run in calibration:
        groups[run.condition].append(run)
    require(len(groups) >= 4, f"the power law (Eq 4.5) needs runs at four or more (feed, speed) conditions; "
                              f"the calibration runs cover {len(groups)}: "
                              + ", ".join(f"{f:g} mm/s {n:g} rpm" for f, n in sorted(groups)))

    fitted = {run.name: run.for_fitting() for run in list(calibration) + list(validation)}
    results: dict[str, RunResult] = {}
    for k, run in enumerate(list(calibration) + list(validation)):
        data = fitted[run.name]
        F0, p = fit_growth(data)
        results[run.name] = RunResult(run, "calibration" if k < len(calibration) else "validation",
                                      fit_friction([data]), F0, p)
    log.info("fitted friction to %d runs one by one", len(results))

    rng = np.random.default_rng(seed)
    conditions = []
    for cond in sorted(groups):
        members = groups[cond]
        names = [r.name for r in members]
        fits = [results[n].fit for n in names]
        reasons = outlier_reasons(names, [f.mu_f for f in fits], [f.mu_w for f in fits],
                                  [f.r2_thrust[0] for f in fits])
        for n, reason in reasons.items():
            results[n].role, results[n].outlier_reason = "outlier", reason
        usable = [n for n in names if n not in reasons]
        if not validation and holdout > 0 and len(usable) >= holdout + 3:
            for n in rng.choice(usable, size=holdout, replace=False):
                results[n].role = "held out"
        used = [n for n in usable if results[n].role == "calibration"]
        require(used, f"no usable runs left at f = {cond[0]:g} mm/s, N = {cond[1]:g} rpm (all outliers?)")
        conditions.append(ConditionResult(cond[0], cond[1], used, [results[n].fit.mu_f for n in used],
                                          [results[n].fit.mu_w for n in used], fit_friction([fitted[n] for n in used]),
                                          _truth(members, "condition_mu_f"), _truth(members, "condition_mu_w")))
    log.info("pooled %d conditions", len(conditions))

    u1 = [cortical_energy_MPa(results[n].fit.initial_force_N[0], results[n].run.feed_mm_s,
                              results[n].run.spindle_rpm, drill) for c in conditions for n in c.runs_used]
    u1_set = float(np.median(u1))
    bone = power_law_set(name, [(c.feed_mm_s, c.spindle_rpm) for c in conditions],
                         [c.mu_f for c in conditions], [c.mu_w for c in conditions], u1_set,
                         u1_set * CANCELLOUS_SPECIFIC_ENERGY_MPA / CORTICAL_SPECIFIC_ENERGY_MPA,
                         source=f"femstudy calibrate: {len(calibration)} runs at {len(conditions)} conditions, "
                                f"drill D = {drill.diameter_mm:g} mm, point angle {drill.point_angle_deg:g} deg")
    for r in results.values():
        if r.role in ("held out", "validation"):
            r.validation = validate(fitted[r.name], bone)
    result = CalibrationResult(list(results.values()), conditions, bone, u1)

    replicates = [r for r in result.runs if r.role in ("calibration", "held out")]
    for label, attr in (("initial cutting force F_o [N]", "eq48_initial_force_N"),
                        ("growth exponent p", "eq48_growth_exponent")):
        pooled = []
        for cond in groups:
            x = np.array([getattr(r, attr) for r in replicates if r.condition == cond])
            if x.size >= 3 and np.std(x) > 0:
                pooled.append((x - x.mean()) / x.std(ddof=1))
        if pooled and sum(p.size for p in pooled) >= 3:
            result.normality[label] = normality(f"{label.split(' [')[0]}, standardised within each condition",
                                                np.concatenate(pooled))
    held = result.by_role("held out", "validation")
    if neurons and held:
        train_runs = [fitted[r.name] for r in result.by_role("calibration")]
        result.ann = ann_module.neuron_study(train_runs, [fitted[r.name] for r in held], neurons, seed=seed)
        best = result.ann.best
        for r in held:
            X, Y = ann_module.run_inputs(fitted[r.name])
            P = best.predict(X)
            r.ann_r2 = (r_squared(Y[:, 0], P[:, 0]), r_squared(Y[:, 1], P[:, 1]))
        log.info("trained networks of %d-%d hidden neurons", result.ann.neurons[0], result.ann.neurons[-1])
    elif not held:
        result.notes.append("no held-out runs (give --validate or keep --holdout > 0 with at least five runs "
                            "per condition): no validation R² and no neural network")
    return result
