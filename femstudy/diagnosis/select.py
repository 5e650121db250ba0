"""Which mechanisms are missing: information criterion, physical size, signatures.

1. BIC of every subset s (its best variant, :mod:`.search`) on the effective sample count:
   BIC(s) = χ²(s) · n_eff/n + k(s) ln n_eff, with χ² inflated per channel by the misfit of the
   largest model, κ² = max(1, χ²_full / (n − k_full)): a simulation error no mechanism explains
   does not make every mechanism look significant. k counts the parameters a fit uses
   (:mod:`.fit`), so a flexible shape pays for every coefficient it needs.
2. From the best subset a mechanism is dropped, weakest first, while any of these fails:
   - drop-one ΔBIC = BIC(s − m) − BIC(s) ≥ ``MIN_DELTA_BIC`` ("very strong" on the Kass–Raftery
     scale; each drop-one subset is also refitted from the larger optimum, and keeps the better);
   - a physically meaningful size (each mechanism's ``floor``);
   - the mechanism's signature tests (:meth:`~.catalogue.Mechanism.checks`): a residual that has
     the size but not the signature of a mechanism is not that mechanism.

   Held-out prediction does not decide: the flexible shapes' local coefficients are unpinned in a
   held-out block, so true mechanisms predict it poorly too (docs/diagnosis.md §8); the held-out
   R² is reported (:mod:`.heldout`).
3. Posterior inclusion probability of each mechanism from the BIC weights exp(−BIC/2).
4. Residual check: the χ² test of the selected model against the noise model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from femstudy.diagnosis.catalogue import MECHANISMS, Check, in_order
from femstudy.diagnosis.confidence import Evidence
from femstudy.diagnosis.fit import Fit, fit
from femstudy.diagnosis.problem import Problem
from femstudy.diagnosis.signatures import refitter

MIN_DELTA_BIC = 10.0
#: A residual χ² test p-value at or below this is "not consistent with noise".
RESIDUAL_P = 1e-3


@dataclass(frozen=True)
class Dropped:
    """A mechanism considered and not kept, and why (with the signature tests it failed)."""

    mechanism: str
    reason: str
    failed: tuple[Check, ...] = ()
    evidence: Evidence | None = None  # for one dropped by its confidence: the evidence it rested on


@dataclass(frozen=True)
class Selection:
    """The selected subset and the evidence for it."""

    subset: frozenset
    bic: dict[frozenset, float]
    inclusion: dict[str, float]
    dropped: tuple[Dropped, ...]
    checks: dict[str, tuple[Check, ...]]
    chi2_per_dof: float
    residual_p_value: float
    inflation: np.ndarray


def n_eff(problem: Problem) -> float:
    return max(problem.n * problem.n_eff_factor, 3.0)


def information(problem: Problem, f: Fit, inflation: np.ndarray) -> float:
    """BIC with the per-channel misfit inflation."""
    return float(np.sum(f.chi2 / inflation)) * problem.n_eff_factor + f.n_params * math.log(n_eff(problem))


def bic_table(problem: Problem, fits: dict) -> tuple[dict, np.ndarray]:
    """BIC of every subset and the per-channel inflation κ² (item 1 of the module)."""
    full = fits[max(fits, key=len)]
    per_channel = np.count_nonzero(problem.usable)
    inflation = np.maximum(1.0, full.chi2 / (per_channel * max(1 - full.n_params / problem.n, 0.1)))
    return {s: information(problem, f, inflation) for s, f in fits.items()}, inflation


def residual_test(problem: Problem, f: Fit) -> tuple[float, float]:
    """χ²/dof and the p-value of the χ² test of ``f``'s residual under the noise model."""
    dof = max(problem.n * problem.n_eff_factor - f.n_params, 1.0)
    chi2 = f.chi2_total * problem.n_eff_factor
    return chi2 / dof, float(stats.chi2.sf(chi2, dof))


def select(problem: Problem, fits: dict) -> Selection:
    """The selected subset with its evidence (see the module docstring)."""
    bic, inflation = bic_table(problem, fits)
    best = min(bic, key=bic.get)
    weights = {s: math.exp(-(b - bic[best]) / 2) for s, b in bic.items()}
    total = sum(weights.values())
    mechanisms = in_order({m for s in fits for m in s})
    inclusion = {m: sum(w for s, w in weights.items() if m in s) / total for m in mechanisms}
    dropped: list[Dropped] = []
    checks: dict[str, tuple[Check, ...]] = {}
    subset = best
    while subset:
        current = fits[subset]
        polished: dict[str, Fit] = {}
        for m in in_order(subset):   # each smaller fit also from the larger optimum
            smaller = subset - {m}
            polished[m] = fit(problem, current.spec.without(m), current.params())
            if polished[m].chi2_total < fits[smaller].chi2_total:
                fits[smaller] = polished[m]
                bic[smaller] = information(problem, polished[m], inflation)
        reasons: dict[str, tuple[float, str]] = {}
        failures: dict[str, tuple[Check, ...]] = {}
        for m in in_order(subset):
            mech = MECHANISMS[m]
            delta = bic[subset - {m}] - bic[subset]
            size = mech.size(problem, current)
            if delta < MIN_DELTA_BIC:
                reasons[m] = (delta, f"drop-one BIC difference {delta:.1f} < {MIN_DELTA_BIC:g}")
            elif size < mech.floor:
                reasons[m] = (delta, f"size {size:.3g} below {mech.floor:g}")
            else:
                found = tuple(mech.checks(problem, current, refitter(problem, m, {id(current): polished[m]})))
                checks[m] = found
                failed = [c for c in found if not c.passed]
                if failed:
                    reasons[m] = (delta - 1e6, "not its signature: " + "; ".join(c.text for c in failed))
                    failures[m] = tuple(failed)
        if not reasons:
            break
        worst = min(reasons, key=lambda m: reasons[m][0])
        dropped.append(Dropped(worst, reasons[worst][1], failures.get(worst, ())))
        subset = subset - {worst}
    chi2_dof, p_value = residual_test(problem, fits[subset])
    return Selection(subset, bic, inclusion, tuple(dropped), {m: checks.get(m, ()) for m in in_order(subset)},
                     chi2_dof, p_value, inflation)
