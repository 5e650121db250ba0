"""The uncertain inputs of a study, their distributions and the sources of their defaults.

Every input is one of two kinds (docs/uncertainty.md):

* **load** inputs change only the drill's thrust and torque histories. The model is linear in
  those, so a sample is a combination of the study's unit responses (:mod:`.response`).
* **stiffness** inputs change K (the regions' moduli scale their parts of K; the clamped length
  changes the fixed DOFs); a sample is solved in a reduced basis whose error is bounded
  (:mod:`.reduced`).

Factors (``*_factor``) multiply the case's nominal value; the others are absolute values in the
unit their name carries. Defaults cite their source; every one can be replaced in the case's
``[uncertainty.distributions]`` table (:class:`femstudy.casefile.InputSpec`).
"""

from __future__ import annotations

import csv
import math
from importlib import resources

import numpy as np

from femstudy import thesis
from femstudy.distributions import INPUTS, Distribution
from femstudy.errors import UserError


#: Tolerances of the operating point where the thesis states none: assumed, to be replaced by a
#: measured one (a drill press's or a robot's specification) in the case file.
FEED_CV = 0.05
SPINDLE_CV = 0.05
DEPTH_CV = 0.10
CLAMP_HALF_RANGE_MM = 5.0
CLAMP_LEVELS = (-1.0, -0.5, 0.0, 0.5, 1.0)


def appendix_b_spread() -> dict:
    """Coefficients of variation of F_o and p over the thirty trials of thesis Table B-1 (one
    condition, f = 1.5 mm/s, N = 1500 rpm), both accepted as normal by the χ² tests of Tables
    4-2 and 4-3."""
    text = resources.files("femstudy.drilling").joinpath("data", "appendix_b_normality_trials.csv").read_text()
    rows = list(csv.DictReader(line for line in text.splitlines() if line and not line.startswith("#")))
    force = np.array([float(r["initial_force_N"]) for r in rows])
    growth = np.array([float(r["growth_exponent_p"]) for r in rows])
    return {"initial_force_cv": float(force.std(ddof=1) / force.mean()),
            "growth_exponent_cv": float(growth.std(ddof=1) / growth.mean()), "trials": len(rows)}


def law_prediction_sd(bone, feed_mm_s: float, spindle_rpm: float, which: str) -> tuple[float, int]:
    """Standard error of ln μ (``which`` "mu_f" or "mu_w") predicted by the bone set's power law
    at (f, N): s √(xᵀ(AᵀA)⁻¹x), s² the residual variance of the least-squares fit of Eq 4.5 over
    the set's calibration conditions, and its degrees of freedom (conditions − 4)."""
    f, n = np.log(np.asarray(bone.feed_mm_s)), np.log(np.asarray(bone.spindle_rpm))
    A = np.column_stack([np.ones_like(f), f, n, f * n])
    y = np.log(np.asarray(getattr(bone, which)))
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    dof = len(y) - 4
    if dof <= 0:
        return float("nan"), 0
    s = math.sqrt(float(np.sum((y - A @ coef) ** 2)) / dof)
    x = np.array([1.0, math.log(feed_mm_s), math.log(spindle_rpm), math.log(feed_mm_s) * math.log(spindle_rpm)])
    return float(s * math.sqrt(x @ np.linalg.solve(A.T @ A, x))), dof


def default_distributions(case, bone, depth_mm: float) -> dict[str, Distribution]:
    """The default distribution of every input for ``case`` (its bone set ``bone`` and drilled
    depth ``depth_mm``), each with its source (docs/uncertainty.md)."""
    spread = appendix_b_spread()
    d = case.drilling
    cv_p, cv_f = spread["growth_exponent_cv"], spread["initial_force_cv"]
    sd_w, dof = law_prediction_sd(bone, d.feed_mm_s, d.spindle_rpm, "mu_w")
    if dof > 0:
        mu_w = Distribution("lognormal", (1.0, sd_w), f"standard error of ln mu_w predicted by the '{bone.name}' "
                            f"set's power law (Eq 4.5) at f = {d.feed_mm_s:g} mm/s, N = {d.spindle_rpm:g} rpm, "
                            f"{dof} residual degree(s) of freedom ({bone.source or bone.name})")
    else:
        mu_w = Distribution("lognormal", (1.0, cv_p), f"the '{bone.name}' set has no residual degree of freedom: "
                            "the trial spread of p (Table B-1, normal by Table 4-3) as for mu_f")
    cortical = thesis.TABLE_3_1["cortical"]["E_MPa"] / 1e3
    cancellous = 0.270 / 0.389  # Table 2-5: SD / mean of the cancellous modulus
    clamp = case.clamps.length_mm
    return {
        "mu_f_factor": Distribution("lognormal", (1.0, cv_p), f"CV {cv_p:.3f} of the growth exponent p over the "
                                    f"{spread['trials']} trials of Table B-1 (normal by the chi-square test of Table "
                                    "4-3); p = eta M D / S is proportional to mu_f"),
        "mu_w_factor": mu_w,
        "cutting_force_factor": Distribution("normal", (1.0, cv_f), f"CV {cv_f:.3f} of the initial cutting force F_o "
                                             f"over the {spread['trials']} trials of Table B-1 (normal by the "
                                             "chi-square test of Table 4-2); F_o scales cutting and evacuation loads"),
        "feed_mm_s": Distribution("normal", (d.feed_mm_s, FEED_CV * d.feed_mm_s),
                                  f"assumed {FEED_CV:.0%} tolerance (the thesis states none)"),
        "spindle_rpm": Distribution("normal", (d.spindle_rpm, SPINDLE_CV * d.spindle_rpm),
                                    f"assumed {SPINDLE_CV:.0%} tolerance (the thesis states none)"),
        "depth_mm": Distribution("normal", (depth_mm, DEPTH_CV * depth_mm),
                                 f"assumed {DEPTH_CV:.0%} spread of the drilled cortex (the mesh keeps its cortex)"),
        "cortical_modulus_factor": Distribution("uniform", (11.7 / cortical, 20.0 / cortical),
                                                "Table 2-1's femoral cortical moduli, 11.7-20.0 GPa, about Table "
                                                f"3-1's {cortical:g} GPa"),
        "cancellous_modulus_factor": Distribution("lognormal", (1.0, math.sqrt(math.log1p(cancellous ** 2))),
                                                  f"CV {cancellous:.2f} of the femoral cancellous modulus (Table 2-5: "
                                                  "0.389 +- 0.270 GPa) about Table 3-1's 0.5 GPa"),
        "clamp_length_mm": Distribution("discrete", tuple(clamp + CLAMP_HALF_RANGE_MM * f for f in CLAMP_LEVELS),
                                        f"assumed: equally likely lengths within +-{CLAMP_HALF_RANGE_MM:g} mm of the "
                                        "case's (the thesis's Figure 3-12 gives no dimension); a few levels, as each "
                                        "clamped node set costs its own reduced basis"),
    }


def distributions(case, bone, depth_mm: float, names: tuple[str, ...] | None = None) -> dict[str, Distribution]:
    """The distributions of the inputs that vary: ``names`` (default: the case's
    ``uncertainty.inputs``), each the case's own (``uncertainty.distributions``) or the default."""
    spec = case.uncertainty
    names = tuple(spec.inputs) if names is None else tuple(names)
    unknown = [n for n in names if n not in INPUTS]
    if unknown:
        raise UserError(f"unknown uncertain input(s) {', '.join(unknown)}: choose from {', '.join(INPUTS)}")
    defaults = default_distributions(case, bone, depth_mm)
    out = {}
    for name in names:
        given = spec.distributions.get(name)
        out[name] = defaults[name] if given is None else given.to_distribution()
    return out


def nominal_values(case, depth_mm: float) -> dict[str, float]:
    """Every input at the case's own value (factors 1)."""
    d = case.drilling
    return {"mu_f_factor": 1.0, "mu_w_factor": 1.0, "cutting_force_factor": 1.0, "feed_mm_s": d.feed_mm_s,
            "spindle_rpm": d.spindle_rpm, "depth_mm": depth_mm, "cortical_modulus_factor": 1.0,
            "cancellous_modulus_factor": 1.0, "clamp_length_mm": case.clamps.length_mm}
