"""Calibrating the chip-evacuation model on processed runs (thesis §4.1.4, §5.1–5.2).

Per run (and, for comparison, over all replicates of a condition at once), the friction coefficients
minimise Eq 4.4's objective over the cut (full engagement to breakthrough):

    Σ_z [ (F_model − F)² + ((T_model − T)/R)² ],
    F_model = F_o exp(p z),   T_model = T_o + R μ_w l_w F_o / M (exp(p z) − 1),

with p = ηMD/S and M = μ_f(l_f + l_h + l_r) + l_w μ_f μ_w sin θ (Eqs 4.1–4.3, evaluated by
:mod:`femstudy.drilling.clogging`). Two decisions the thesis leaves open:

- F_o is free for every run (the thesis normalises each run by its own initial force, §4.5.2),
  and so is T_o: Eq 4.2 is the evacuation torque alone (zero at z = 0) while the measured
  torque also carries the cutting torque, which :mod:`femstudy.drilling.history` adds.
  For given (μ_f, μ_w) both enter linearly and are solved exactly (variable projection), so
  the nonlinear search (``scipy.optimize.least_squares``, in ln μ) has two unknowns.
- **Identifiability.** With F_o free, the thrust fixes only p, i.e. the product
  μ_f·(l_f + l_h + l_r + l_w μ_w sin θ). The torque's rise relative to the thrust,
  R μ_w l_w / M, then fixes μ_w, and μ_f follows from M. The wall's share of M is only
  w ≈ 0.17 (docs/load-models.md), so an error δ in ln μ_w moves ln μ_f by just −w·δ, and the
  two estimates are nearly uncorrelated (:attr:`FrictionFit.correlation`, about +0.1).
  μ_f inherits every error of the thrust's growth rate: a slow feed pulsation, which bends
  the rise, is the worst (7 % rms per run on the synthetic data set). μ_w rests on the ratio
  of torque to thrust, in which a modulation common to both cancels (3.7 % rms). Without
  pulsation both are recovered to a few tenths of a per cent.

Across conditions the power law (Eqs 4.5–4.7) is :func:`femstudy.drilling.friction.fit_power_law`,
through :class:`~femstudy.drilling.friction.BoneSet`. Validation (Table 5-4) predicts a
held-out run's curves from the power law, with only its own initial loads F_o and T_o
fitted, and reports R² = 1 − SS_res/SS_tot (SS_tot about the mean of the observations; the
thesis's Eq 5.5 writes the prediction there, a slip).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from femstudy.drilling import allotta, clogging
from femstudy.drilling.drill import Drill, feed_per_revolution
from femstudy.drilling.friction import BoneSet
from femstudy.errors import require
from femstudy.recordings.processing import ProcessedRun

MU_BOUNDS = (1e-3, 20.0)
#: A run is an outlier when |ln μ − median| exceeds 3.5 robust standard deviations (the
#: modified z-score of Iglewicz & Hoaglin) ...
OUTLIER_Z = 3.5
#: ... with the robust standard deviation 1.4826·MAD of ln μ, but at least 0.1 (10 %): with a
#: handful of nearly identical runs the MAD can be tiny, and a 5 % difference is no outlier.
#: Real replicate scatter is larger (Appendix B: 16 % robust spread of p).
MIN_LN_SPREAD = 0.1
#: A run whose own Eq 4.4 fit explains less than this share of its thrust variance is an outlier.
MIN_OWN_R2 = 0.5


def r_squared(observed, predicted) -> float:
    """Coefficient of determination 1 − Σ(y − ŷ)² / Σ(y − ȳ)² (Eq 5.3 with the usual SS_tot)."""
    y, yhat = np.asarray(observed, float), np.asarray(predicted, float)
    total = float(np.sum((y - y.mean()) ** 2))
    return 1.0 - float(np.sum((y - yhat) ** 2)) / total if total > 0 else float("nan")


def unit_curves(z, mu_f: float, mu_w: float, drill: Drill) -> tuple[np.ndarray, np.ndarray]:
    """exp(p z) and T_c(z)/F_o [mm]: the model's thrust and evacuation torque for F_o = 1 N."""
    return clogging.thrust(z, 1.0, mu_f, mu_w, drill), clogging.torque(z, 1.0, mu_f, mu_w, drill)


def initial_loads(run: ProcessedRun, mu_f: float, mu_w: float) -> tuple[float, float]:
    """F_o [N] and T_o [N·mm] minimising Eq 4.4 for given friction (a 2×2 linear solve)."""
    g, h = unit_curves(run.z, mu_f, mu_w, run.drill)
    R2 = run.drill.radius_mm ** 2
    F, T = run.thrust_N, run.torque_Nmm
    A = np.array([[g @ g + h @ h / R2, h.sum() / R2], [h.sum() / R2, g.size / R2]])
    rhs = np.array([g @ F + h @ T / R2, T.sum() / R2])
    F0, T0 = np.linalg.solve(A, rhs)
    return float(F0), float(T0)


def model_loads(z, drill: Drill, mu_f: float, mu_w: float, F0: float, T0: float):
    """Thrust F_o exp(p z) [N] and torque T_o + T_c(z) [N·mm] of the model at depths z."""
    g, h = unit_curves(z, mu_f, mu_w, drill)
    return F0 * g, T0 + F0 * h


def _residuals(log_mu, runs: list[ProcessedRun]) -> np.ndarray:
    mu_f, mu_w = np.exp(log_mu)
    parts = []
    for run in runs:
        F0, T0 = initial_loads(run, mu_f, mu_w)
        F, T = model_loads(run.z, run.drill, mu_f, mu_w, F0, T0)
        parts += [F - run.thrust_N, (T - run.torque_Nmm) / run.drill.radius_mm]
    return np.concatenate(parts)


def fit_growth(run: ProcessedRun) -> tuple[float, float]:
    """(F_o [N], p) of F = F_o exp(p z) fitted to the thrust alone (Eq 4.8, Appendix B)."""
    z, F = run.z, run.thrust_N
    positive = F > 0
    slope, intercept = np.polyfit(z[positive], np.log(F[positive]), 1) if positive.sum() > 2 else (0.0, 0.0)

    def res(x):
        return x[0] * np.exp(x[1] * z) - F

    sol = optimize.least_squares(res, [math.exp(intercept), slope], method="lm")
    return float(sol.x[0]), float(sol.x[1])


@dataclass(frozen=True)
class FrictionFit:
    """μ_f, μ_w fitted to one or more runs, with each run's initial loads and fit quality."""

    mu_f: float
    mu_w: float
    initial_force_N: tuple[float, ...]
    initial_torque_Nmm: tuple[float, ...]
    r2_thrust: tuple[float, ...]
    r2_torque: tuple[float, ...]
    correlation: float  # of the ln μ_f and ln μ_w estimates, from the Jacobian
    drill: Drill

    @property
    def growth_exponent(self) -> float:
        """p = ηMD/S at the fitted friction."""
        return clogging.growth_exponent(self.mu_f, self.mu_w, self.drill)


def fit_friction(runs: list[ProcessedRun]) -> FrictionFit:
    """Eq 4.4 over one run or the pooled replicates of a condition (shared μ, own F_o, T_o)."""
    require(len(runs) > 0, "no runs to calibrate")
    for run in runs:
        require(run.torque_Nmm is not None, f"recording {run.name} has no torque column; calibrating "
                                            f"μ_f and μ_w needs torque (Eq 4.4)")
    drill = runs[0].drill
    require(all(r.drill == drill for r in runs), "runs fitted together must use the same drill")
    M = np.mean([max(fit_growth(r)[1], 0.05) for r in runs]) * drill.flute_area_mm2 / (drill.eta * drill.diameter_mm)
    sin_theta = math.sin(math.radians(drill.face_angle_deg))
    bounds = np.log(MU_BOUNDS)
    best = None
    for mu_w0 in (0.2, 0.6, 2.0):
        mu_f0 = float(np.clip(M / (drill.flute_length_sum_mm + drill.wall_mm * mu_w0 * sin_theta), *MU_BOUNDS))
        sol = optimize.least_squares(_residuals, np.log([mu_f0, mu_w0]), args=(runs,),
                                     bounds=(bounds[0], bounds[1]), x_scale=1.0, jac="3-point",
                                     xtol=1e-12, ftol=1e-12, gtol=1e-12)
        if best is None or sol.cost < best.cost:
            best = sol
    mu_f, mu_w = (float(v) for v in np.exp(best.x))
    try:
        cov = np.linalg.inv(best.jac.T @ best.jac)
        corr = float(cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1]))
    except np.linalg.LinAlgError:
        corr = float("nan")
    loads = [initial_loads(r, mu_f, mu_w) for r in runs]
    curves = [model_loads(r.z, r.drill, mu_f, mu_w, *l) for r, l in zip(runs, loads)]
    return FrictionFit(mu_f=mu_f, mu_w=mu_w, initial_force_N=tuple(l[0] for l in loads),
                       initial_torque_Nmm=tuple(l[1] for l in loads),
                       r2_thrust=tuple(r_squared(r.thrust_N, c[0]) for r, c in zip(runs, curves)),
                       r2_torque=tuple(r_squared(r.torque_Nmm, c[1]) for r, c in zip(runs, curves)),
                       correlation=corr, drill=drill)


def outlier_reasons(names: list[str], mu_f, mu_w, r2_thrust) -> dict[str, str]:
    """Runs of one condition that trend differently, each with the reason.

    Criterion: |ln μ − median| / max(1.4826·MAD, 0.1) > 3.5 for μ_f or μ_w (robust to the
    outliers themselves; needs at least 4 runs), or an own fit with R² < 0.5.
    """
    reasons: dict[str, str] = {}
    if len(names) >= 4:
        for label, values in (("mu_f", mu_f), ("mu_w", mu_w)):
            x = np.log(np.asarray(values, float))
            med = float(np.median(x))
            spread = max(1.4826 * float(np.median(np.abs(x - med))), MIN_LN_SPREAD)
            for name, xi, v in zip(names, x, values):
                score = (xi - med) / spread
                if abs(score) > OUTLIER_Z and name not in reasons:
                    reasons[name] = (f"{label} = {v:.4g} is {abs(score):.1f} robust SDs "
                                     f"{'above' if score > 0 else 'below'} the condition median "
                                     f"{math.exp(med):.4g} (limit {OUTLIER_Z})")
    for name, r2 in zip(names, r2_thrust):
        if name not in reasons and not r2 >= MIN_OWN_R2:
            reasons[name] = f"its thrust does not follow Eq 4.1 (own fit R² = {r2:.2f} < {MIN_OWN_R2})"
    return reasons


def cortical_energy_MPa(initial_force_N: float, feed_mm_s: float, spindle_rpm: float, drill: Drill) -> float:
    """u1 [MPa] from F_o = a sin(β/2) tan(β/2) u1 l, Allotta's full-engagement thrust."""
    F_unit, _ = allotta.full_engagement(feed_per_revolution(feed_mm_s, spindle_rpm), 1.0, drill)
    return initial_force_N / F_unit


def power_law_set(name: str, conditions: list[tuple[float, float]], mu_f, mu_w, u1_MPa: float, u2_MPa: float,
                  source: str) -> BoneSet:
    """The bone set of per-condition friction; its power law is Eqs 4.5–4.7 by least squares."""
    require(len(conditions) >= 4, f"the power law (Eq 4.5) has four coefficients and needs at least four "
                                   f"(feed, speed) conditions; the runs cover {len(conditions)}")
    return BoneSet(name=name, feed_mm_s=tuple(c[0] for c in conditions),
                   spindle_rpm=tuple(c[1] for c in conditions), mu_f=tuple(float(m) for m in mu_f),
                   mu_w=tuple(float(m) for m in mu_w), u1_MPa=float(u1_MPa), u2_MPa=float(u2_MPa),
                   source=source)


@dataclass(frozen=True)
class Validation:
    """A held-out run predicted by the power law (Table 5-4)."""

    name: str
    feed_mm_s: float
    spindle_rpm: float
    mu_f: float
    mu_w: float
    initial_force_N: float
    initial_torque_Nmm: float
    r2_thrust: float
    r2_torque: float


def validate(run: ProcessedRun, bone: BoneSet) -> Validation:
    """Predict a run from the power law at its (f, N); only F_o and T_o are fitted to it."""
    mu_f, mu_w = bone.friction(run.feed_mm_s, run.spindle_rpm)
    F0, T0 = initial_loads(run, mu_f, mu_w)
    F, T = model_loads(run.z, run.drill, mu_f, mu_w, F0, T0)
    return Validation(run.name, run.feed_mm_s, run.spindle_rpm, mu_f, mu_w, F0, T0,
                      r_squared(run.thrust_N, F), r_squared(run.torque_Nmm, T))
