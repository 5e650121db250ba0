"""Fit improvement that predicts: R² of the cut from fits that did not see it (blocked folds).

The in-sample R² of a model with a dozen free parameters flatters it. Here the cutting window is
split into ``BLOCKS`` contiguous blocks; each block is predicted by the same model (mechanisms in
their variants, tares, drift) refitted on everything else — the other blocks and the load-free
instants — with the alignment held at the full fit's. The held-out R² is
1 − Σ(y − ŷ_held)² / Σ(y − ȳ)² over the window, on the smoothed recording, per channel. A
mechanism that only bends the curve to the data it saw predicts the blocks it did not worse
than the simulation alone.

A mechanism's shape coefficient whose basis function lies almost wholly inside the held-out
block (less than :data:`MIN_SUPPORT` of its weight on the rows refitted) cannot be learned from
the rest: free, it takes any value the bounds allow (a clogging's last I-splines, whose rise lies
in the block, reached twice the initial force in one benchmark case and a held-out R² of −2).
Such a coefficient is held at zero when zero is allowed: the mechanism goes on inside the block
as the rest of the data shows (a monotone excess stays level, a loss grows no further).
"""

from __future__ import annotations

import numpy as np

from femstudy.diagnosis.fit import Fit, fit
from femstudy.diagnosis.problem import Problem

BLOCKS = 4
#: Held at the full fit's values in every refit: the clock shift and the stop depth are pinned by a
#: few instants that a block may hold out, and they are not what is being predicted.
ALIGNMENT = ("shift_correction_s", "stop_correction_mm")
#: Least share of a mechanism coefficient's weight (the squared norm of its derivatives) on the
#: rows a held-out refit sees for it to be refitted; below, it is held at zero.
MIN_SUPPORT = 0.05


def block_masks(window: np.ndarray, blocks: int = BLOCKS) -> list[np.ndarray]:
    """Boolean masks of ``blocks`` contiguous, nearly equal runs of the ``window`` instants."""
    idx = np.flatnonzero(window)
    return [np.isin(np.arange(window.size), part) for part in np.array_split(idx, blocks) if part.size]


def held_out_predictions(problem: Problem, f: Fit, window: np.ndarray) -> np.ndarray:
    """The smoothed model, channels × instants, each block of ``window`` predicted by a fit
    without it (the full fit's model elsewhere)."""
    out = f.model.copy()
    for block in block_masks(window):
        unsupported = unsupported_coefficients(problem, f, ~block)
        start = {**f.params(), **{name: 0.0 for name in unsupported}}
        refit = fit(problem, f.spec, start, rows=~block, fixed=ALIGNMENT + unsupported)
        out[:, block] = refit.model[:, block]
    return out


def unsupported_coefficients(problem: Problem, f: Fit, rows: np.ndarray) -> tuple[str, ...]:
    """The mechanism coefficients of ``f`` with less than :data:`MIN_SUPPORT` of their weight on
    ``rows`` (of the usable instants) and zero within their bounds."""
    J = f.evaluation.jacobian
    seen = rows & problem.usable
    total = np.einsum("cip,cip->p", J[:, problem.usable], J[:, problem.usable])
    kept = np.einsum("cip,cip->p", J[:, seen], J[:, seen])
    lay = f.layout
    return tuple(lay.names[k] for block in lay.blocks.values() for k in range(block.start, block.stop)
                 if total[k] > 0 and kept[k] < MIN_SUPPORT * total[k] and lay.lower[k] <= 0.0 <= lay.upper[k])


def r2(y: np.ndarray, prediction: np.ndarray) -> float:
    """1 − Σ(y − ŷ)² / Σ(y − ȳ)²."""
    return float(1 - np.sum((y - prediction) ** 2) / max(float(np.sum((y - y.mean()) ** 2)), 1e-300))
