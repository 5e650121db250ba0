"""The verdict: which mechanisms are named, how confident, and what is left unexplained.

1. The selection (:mod:`.select`) names a subset S of the catalogue.
2. **Replacement test**: mechanisms M ⊆ S are not named when a single shape that no catalogue
   mechanism produces (:func:`.openworld.competitors`: a step, a bump, a timing error, a
   load-power excess, a one-channel change or oscillation) explains the data clearly better in
   their place: BIC(S − M + shape) < BIC(S) − ``MIN_DELTA_BIC``, with the selection's misfit
   inflation (mechanisms, the physics expected a priori, keep the benefit of the doubt). The
   best shape of each kind is found on the residual of S − M, then S − M is refitted with its
   columns (alignment, tares and the remaining mechanisms follow it); the largest BIC gain
   wins, provided M is not still needed beside the shape (BIC(S + shape) is not lower than
   BIC(S − M + shape) by ``MIN_DELTA_BIC``: a step late in the cut must not stand in for a drift
   seen before contact); repeated until nothing is replaced. Every kind is refitted, not only the one with the
   largest gain on the residual: the refit can reverse their order (a harder layer's bump
   against a one-channel oscillation). This is what keeps a chip breaking off from being named
   softening, a thrust-only vibration feed pulsation, or a harder layer clogging.
3. **Unexplained**: the residual of the named model is characterised (:func:`.openworld.characterise`).
4. **Confidence** of a named mechanism: its posterior inclusion probability (BIC weights)
   times the share of the mismatch the final model explains, 1 − excess(final)/excess(baseline)
   with excess = max(χ² − dof, 0) under the noise model; when the final residual is not
   consistent with noise it is at most ``FAILED_TEST_CAP``. A confidence near 1 thus says both
   that the mechanism is needed and that the model with it explains the recording.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from femstudy.diagnosis import openworld
from femstudy.diagnosis.fit import Fit, fit_each
from femstudy.diagnosis.mechanisms import Problem
from femstudy.diagnosis.mechanisms.registry import in_order
from femstudy.diagnosis.select import MIN_DELTA_BIC, RESIDUAL_P, Selection

#: Highest confidence when the final residual is not consistent with noise.
FAILED_TEST_CAP = 0.8


@dataclass(frozen=True)
class Verdict:
    """The named subset, its fit, the shapes left unexplained and the confidences."""

    subset: frozenset
    fit: Fit
    shapes: tuple
    dropped: dict                  # mechanism -> the shape that replaced it
    confidence: dict               # mechanism -> confidence
    chi2_per_dof: float
    residual_p_value: float

    @property
    def consistent_with_noise(self) -> bool:
        return self.residual_p_value > RESIDUAL_P


def residual_test(problem: Problem, fit: Fit) -> tuple[float, float]:
    """χ²/dof and the p-value of the χ² test of ``fit``'s residual under the noise model."""
    dof = max(problem.y.size * problem.n_eff_factor - fit.n_params, 1.0)
    chi2 = fit.chi2_total * problem.n_eff_factor
    return chi2 / dof, float(stats.chi2.sf(chi2, dof))


def _excess(problem: Problem, fit: Fit) -> float:
    return max(fit.chi2_total * problem.n_eff_factor - (problem.y.size * problem.n_eff_factor - fit.n_params), 0.0)


def _bic(problem: Problem, chi2: np.ndarray, n_params: int, inflation: np.ndarray) -> float:
    n_eff = problem.y.size * problem.n_eff_factor
    return float(np.sum(chi2 / inflation)) * problem.n_eff_factor + n_params * math.log(n_eff)


def replace_by_shapes(problem: Problem, fits: dict, subset: frozenset, inflation: np.ndarray,
                      fits_of=fit_each) -> tuple[frozenset, dict]:
    """Step 2 of the module: the subset left once a shape has replaced what it explains better.
    Every proper part S' of the named subset S is tried with the best competing shape of each
    kind on the residual of S' (one shape may stand in for several mechanisms that together
    mimic it)."""
    dropped = {}
    bic = lambda fit, shape: _bic(problem, fit.chi2, fit.n_params + shape.scanned, inflation)
    while subset:
        full = _bic(problem, fits[subset].chi2, fits[subset].n_params, inflation)
        tried = [(frozenset(kept), shape) for size in range(len(subset))
                 for kept in itertools.combinations(sorted(subset), size)
                 for shape in openworld.competitors(problem, fits[frozenset(kept)].params,
                                                    problem.y - fits[frozenset(kept)].model)]
        refits = _with_shapes(problem, [(fits[kept], shape) for kept, shape in tried], fits_of)
        scored = [(bic(refit, shape), kept, shape) for (kept, shape), refit in zip(tried, refits)]
        better = sorted((b for b in scored if full - b[0] >= MIN_DELTA_BIC), key=lambda b: b[0])

        def still_needed(replaced, _, shape) -> bool:
            """The dropped mechanisms, refitted beside the shape, still gain MIN_DELTA_BIC."""
            beside, = _with_shapes(problem, [(fits[subset], shape)], fits_of)
            return replaced - bic(beside, shape) >= MIN_DELTA_BIC

        best = next((b for b in better if not still_needed(*b)), None)  # the largest gain that holds
        if best is None:
            break
        replaced, kept, shape = best
        delta = full - replaced
        kind, channel, _ = openworld.describe(problem, shape)
        for m in in_order(subset - kept):
            dropped[m] = (f"a {kind.replace('_', ' ')} ({channel}) explains the data better in its place "
                          f"(BIC lower by {delta:.1f})")
        subset = kept
    return subset, dropped


def _with_shapes(problem: Problem, pairs: list, fits_of=fit_each) -> list[Fit]:
    """Each (fit, shape): the fit's subset refitted with the shape's columns added (its scanned
    parameters held), so that the alignment and the tares can follow the shape."""
    return fits_of([(replace(problem, extra=shape.free_columns()), fit.subset,
                     [{n: fit.params[n] for n in problem.nonlinear_names(fit.subset, fit.variant)}],
                     {"variant": fit.variant}) for fit, shape in pairs])


def decide(problem: Problem, fits: dict, selection: Selection, baseline: Fit, fits_of=fit_each) -> Verdict:
    """Steps 2–4 of the module (refits by ``fits_of``, :mod:`.workers`)."""
    subset, dropped = replace_by_shapes(problem, fits, selection.subset, selection.inflation, fits_of)
    fit = fits[subset]
    found = openworld.characterise(problem, fit.params, problem.y - fit.model)
    chi2_dof, p_value = residual_test(problem, fit)
    base_excess = _excess(problem, baseline)
    share = 1.0 - _excess(problem, fit) / base_excess if base_excess > 0 else 1.0
    cap = 1.0 if p_value > RESIDUAL_P else FAILED_TEST_CAP
    confidence = {m: round(float(selection.confidence.get(m, 0.0) * min(max(share, 0.0), cap)), 4) for m in in_order(subset)}
    return Verdict(subset, fit, tuple(found), dropped, confidence, chi2_dof, p_value)
