"""Fit improvement that predicts: R² of the cut from fits that did not see it (blocked folds).

The in-sample R² of a model with a dozen free parameters flatters it. Here the cutting
window is split into ``BLOCKS`` contiguous blocks; each block is predicted by the same
model (mechanisms, tares, drift) refitted on everything else — the other blocks and the
load-free instants — with the alignment (clock shift, a load model's stop) and clogging's
retained fraction held at the full fit's values, as each is pinned by a few instants a block
may contain. The held-out R² is
1 − Σ(y − ŷ_held)² / Σ(y − ȳ)² over the window, on the smoothed recording, per channel.
A mechanism that only bends the curve to the data it saw predicts the blocks it did not
worse than the simulation alone.
"""

from __future__ import annotations

import numpy as np

from femstudy.diagnosis.fit import Fit, fit_each
from femstudy.diagnosis.mechanisms import Problem

BLOCKS = 4


def block_masks(window: np.ndarray, blocks: int = BLOCKS) -> list[np.ndarray]:
    """Boolean masks of ``blocks`` contiguous, nearly equal runs of the ``window`` instants."""
    idx = np.flatnonzero(window)
    return [np.isin(np.arange(window.size), part) for part in np.array_split(idx, blocks) if part.size]


def held_out_predictions(problem: Problem, fit: Fit, window: np.ndarray, fits_of=fit_each) -> np.ndarray:
    """The smoothed model at the window's instants, each block predicted from a fit without it.

    Parameters
    ----------
    problem : the diagnosis problem (its noise model weights the refits).
    fit : the fit whose subset and parameters start each refit.
    window : boolean mask of the instants predicted (the cut).
    fits_of : the fitter of the refits (:mod:`.workers`).

    Returns
    -------
    numpy.ndarray, channels × instants: the held-out prediction in the window, the full
    fit's model elsewhere.

    Examples
    --------
    >>> pred = held_out_predictions(problem, fit, window)  # doctest: +SKIP
    """
    names = problem.nonlinear_names(fit.subset, fit.variant)
    alignment = {n: fit.params[n] for n in problem.held_out_fixed_names(fit.subset)}
    start = {n: fit.params[n] for n in names}
    out = fit.model.copy()
    blocks = block_masks(window)
    refits = fits_of([(problem, fit.subset, [start], {"rows": ~b, "variant": fit.variant, "fixed": alignment})
                      for b in blocks])
    for block, refit in zip(blocks, refits):
        out[:, block] = refit.model[:, block]
    return out


def r2(y: np.ndarray, prediction: np.ndarray) -> float:
    """1 − Σ(y − ŷ)² / Σ(y − ȳ)²."""
    return float(1 - np.sum((y - prediction) ** 2) / max(float(np.sum((y - y.mean()) ** 2)), 1e-300))
