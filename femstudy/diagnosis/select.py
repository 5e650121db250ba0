"""Which mechanisms are missing: information criterion, held-out prediction, effect size.

1. BIC of every subset s on the effective sample count n_eff (see :mod:`.band`):

       BIC(s) = χ²(s) · n_eff/n + k(s) ln n_eff,

   where χ² uses the data's noise level, inflated per channel by the misfit of the largest
   model, κ² = max(1, χ²_full / (n − k_full)), so that a simulation error no mechanism
   explains does not make every mechanism look significant.
2. Starting from the best subset, a mechanism is dropped while any one fails (each drop-one
   subset is first refitted from the larger subset's optimum, and keeps the better fit):
   - drop-one ΔBIC = BIC(s − m) − BIC(s) ≥ ``MIN_DELTA_BIC`` ("very strong" evidence on the
     Kass–Raftery scale);
   - a physically meaningful size (each mechanism's ``threshold``, :mod:`.mechanisms`);
   - held-out prediction: in a K-fold split into contiguous blocks of the compared window,
     the subset with the mechanism predicts the held-out blocks better than without it.
3. Confidence of each mechanism: its posterior inclusion probability from the BIC weights
   exp(−BIC/2) of all subsets (the share of evidence carried by subsets that contain it).
4. Residual check: χ²/dof of the selected model against the noise level (p-value of the
   χ² test) says whether what remains is noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from femstudy.diagnosis.fit import Fit, fit_each
from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.mechanisms.registry import catalogue, in_order, mechanism, owner

MIN_DELTA_BIC = 10.0
#: A residual χ² test p-value at or below this is "not consistent with noise".
RESIDUAL_P = 1e-3
FOLDS = 5
@dataclass
class Selection:
    """The selected subset and the evidence for it."""

    subset: frozenset
    bic: dict                    # subset -> BIC
    confidence: dict             # mechanism -> posterior inclusion probability
    dropped: dict                # mechanism -> reason it was not kept
    held_out: dict               # subset -> held-out χ²
    chi2_per_dof: float
    residual_p_value: float
    inflation: np.ndarray


def bic_table(problem: Problem, fits: dict) -> tuple[dict, np.ndarray]:
    """BIC of every subset and the per-channel misfit inflation κ² (item 1 of the module)."""
    full = max(fits, key=len)
    n = problem.y.size
    n_eff = n * problem.n_eff_factor
    per_channel = problem.y.shape[1]
    k_full = fits[full].n_params
    inflation = np.maximum(1.0, fits[full].chi2 / (per_channel * (1 - k_full / n)))
    table = {s: float(np.sum(f.chi2 / inflation)) * problem.n_eff_factor + f.n_params * math.log(n_eff)
             for s, f in fits.items()}
    return table, inflation


def effect_sizes(problem: Problem, fit: Fit) -> dict:
    """Size of each mechanism of a fit, in the units of its threshold: the smallest size that
    counts as missing physics (clogging rise by breakthrough and softening loss by the end of
    the cut, fractions of the load; pulsation amplitude, a fraction of the feed; drift over the
    recording, a fraction of the peak simulated load). The thresholds keep a mechanism from
    soaking up a small simulation error in the cut."""
    return {m.name: m.size(problem, fit.params) for m in catalogue() if m.name in fit.subset}


def folds(problem: Problem) -> list[np.ndarray]:
    """Row masks of the held-out block of each fold: ``FOLDS`` contiguous blocks of the
    compared window, so that a mechanism must predict a stretch it has not seen rather than
    interpolate between neighbours (which any combination of slow terms can)."""
    t = problem.band.t_dec
    block = np.minimum(np.floor((t - t[0]) / (t[-1] - t[0] + 1e-12) * FOLDS).astype(int), FOLDS - 1)
    return [block == k for k in range(FOLDS)]


def held_out_chi2(problem: Problem, fits: list[Fit], inflation: np.ndarray, fits_of=fit_each) -> list[float]:
    """Σ over folds of the χ² of held-out segments, each predicted by a fit on the others. The
    alignment (shift, stop depth) and clogging's retained fraction stay at the full fit's values
    (:meth:`~.mechanisms.Problem.held_out_fixed_names`): each is pinned by a few instants that a
    fold may hold out, and they are not what is being tested. One value per fit of ``fits``."""
    held = folds(problem)
    requests = []
    for fit in fits:
        names = problem.nonlinear_names(fit.subset, fit.variant)
        options = {"variant": fit.variant,
                   "fixed": {n: fit.params[n] for n in problem.held_out_fixed_names(fit.subset)}}
        requests += [(problem, fit.subset, [{n: fit.params[n] for n in names}], {**options, "rows": ~h})
                     for h in held]
    refits = fits_of(requests)
    chi2 = [float(sum(np.sum(problem.whiten(c, problem.y[c] - f.model[c], h) ** 2) / k for c, k in enumerate(inflation)))
            for f, h in zip(refits, held * len(fits))]
    return [sum(chi2[i * len(held):(i + 1) * len(held)]) for i in range(len(fits))]


def select(problem: Problem, fits: dict, fits_of=fit_each) -> Selection:
    """The selected subset, with the evidence (see the module docstring); refits by
    ``fits_of`` (:mod:`.workers`)."""
    bic, inflation = bic_table(problem, fits)
    best = min(bic, key=bic.get)
    weights = {s: math.exp(-(b - bic[best]) / 2) for s, b in bic.items()}
    total = sum(weights.values())
    mechanisms = in_order({m for s in fits for m in s})
    confidence = {m: sum(w for s, w in weights.items() if m in s) / total for m in mechanisms}

    dropped, held_out = {}, {}
    subset = best
    n_eff = problem.y.size * problem.n_eff_factor
    while subset:
        # each smaller fit also from the larger optimum: fits are multimodal
        smallers = [subset - {m} for m in in_order(subset)]
        variant = fits[subset].variant
        polishes = fits_of([(problem, s, [{n: fits[subset].params[n] for n in problem.nonlinear_names(s, variant)}],
                                      {"variant": tuple(v for v in variant if owner(v).name in s)})
                             for s in smallers])
        for smaller, polished in zip(smallers, polishes):
            if polished.chi2_total < fits[smaller].chi2_total:
                fits[smaller] = polished
                bic[smaller] = (float(np.sum(polished.chi2 / inflation)) * problem.n_eff_factor
                                + polished.n_params * math.log(n_eff))
        reasons = {}
        sizes = effect_sizes(problem, fits[subset])
        for m in in_order(subset):
            delta = bic[subset - {m}] - bic[subset]
            if delta < MIN_DELTA_BIC:
                reasons[m] = (delta, f"drop-one BIC difference {delta:.1f} < {MIN_DELTA_BIC:g}")
            elif sizes[m] < mechanism(m).threshold:
                reasons[m] = (delta, f"size {sizes[m]:.3g} below {mechanism(m).threshold:g}")
        if not reasons:
            missing = [s for s in [subset] + [subset - {m} for m in in_order(subset)] if s not in held_out]
            held_out.update(zip(missing, held_out_chi2(problem, [fits[s] for s in missing], inflation, fits_of)))
            for m in in_order(subset):
                if held_out[subset - {m}] <= held_out[subset]:
                    reasons[m] = (held_out[subset - {m}] - held_out[subset],
                                  f"does not improve held-out prediction "
                                  f"({held_out[subset]:.1f} with, {held_out[subset - {m}]:.1f} without)")
        if not reasons:
            break
        worst = min(reasons, key=lambda m: reasons[m][0])
        dropped[worst] = reasons[worst][1]
        subset = subset - {worst}

    fit = fits[subset]
    dof = max(problem.y.size * problem.n_eff_factor - fit.n_params, 1.0)
    chi2 = fit.chi2_total * problem.n_eff_factor
    return Selection(subset, bic, confidence, dropped, held_out, chi2 / dof,
                     float(stats.chi2.sf(chi2, dof)), inflation)
