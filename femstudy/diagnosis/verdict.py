"""The verdict: which mechanisms are named, and what is left unexplained.

1. The selection (:mod:`.select`) names a subset S of the catalogue.
2. **Replacement test**: mechanisms M ⊆ S are not named when a single shape that no catalogue
   mechanism produces (:func:`.outside.competitors`) explains the data clearly better in their
   place: BIC(S − M + shape) < BIC(S) − ``MIN_DELTA_BIC`` with the selection's misfit inflation
   (mechanisms, the physics expected a priori, keep the benefit of the doubt). The best shape of
   each kind is found on the residual of S − M, then S − M is refitted with its columns
   (alignment, tares and the remaining mechanisms follow it); the lowest BIC wins. Each mechanism
   of M then stands only if it is still needed beside the shape (S + shape lower than
   S − m + shape by ``MIN_DELTA_BIC`` and by ``BESIDE_SHARE`` of what the shape gained: less is
   the shape's form being imperfect) with a size above its floor there and at least
   ``BESIDE_SIZE_SHARE`` of its size without the shape (a shape that takes most of a
   mechanism's size explains what the mechanism explained; what is left of the mechanism is
   the shape's imperfect form again); this repeats until nothing is replaced.
3. **Unexplained**: the residual of the named model is characterised (:func:`.outside.characterise`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from femstudy.diagnosis import outside
from femstudy.diagnosis.catalogue import MECHANISMS, in_order
from femstudy.diagnosis.fit import Fit
from femstudy.diagnosis.fitpool import FitPool, portable, restored
from femstudy.diagnosis.problem import Problem
from femstudy.diagnosis.select import MIN_DELTA_BIC, Dropped, information, n_eff


#: A mechanism stands beside a shape that replaced it when it gains this share of what the shape
#: gained (or MIN_DELTA_BIC, whichever is more): less is the shape's form being imperfect.
BESIDE_SHARE = 0.05
#: ... and keeps at least this share of the size it has without the shape (a majority: the
#: shape must not have taken most of it). On the tuning split (formbench seed 1) the mechanisms
#: that stood beside a shape kept 0.87-1.0 of their size, bar one that kept 0.19: a clogging
#: named on a spindle-slowdown decoy.
BESIDE_SIZE_SHARE = 0.5


@dataclass(frozen=True)
class Verdict:
    """The named subset, its fit, the shapes left unexplained and what the shapes replaced."""

    subset: frozenset
    fit: Fit
    shapes: tuple[outside.Shape, ...]
    replaced: tuple[Dropped, ...]
    replacement_margin: dict[str, float]    #: per named mechanism, how far the best replacement fell short (BIC)


def _with_shape(f: Fit, shape: outside.Shape) -> tuple:
    """The task (spec, start) of refitting ``f`` with ``shape``'s columns beside its mechanisms."""
    return f.spec.with_extra(shape.free_columns()), f.params()


def _competitors(problem: Problem, sent: tuple) -> list[outside.Shape]:
    """The competing shapes on the residual of a fit sent as :func:`.fitpool.portable`."""
    f = restored(problem, sent)
    return outside.competitors(problem, f, problem.y - f.model)


def replace_by_shapes(problem: Problem, fits: dict, subset: frozenset, inflation,
                      pool: FitPool) -> tuple[frozenset, tuple, dict]:
    """Item 2 of the module: the subset left once shapes have replaced what they explain better,
    the replacements, and per kept mechanism the margin by which its best replacement failed.
    The scans of the smaller subsets' residuals, and the refits with their shapes, run side by
    side in ``pool``, each subset's once (a replacement leaves a subset whose smaller subsets were
    all scanned already)."""
    replaced: list[Dropped] = []
    margins: dict[str, float] = {}
    scanned: dict[frozenset, list] = {}   # a smaller subset's shapes and refits with them, once per subset

    def bic(f: Fit, shape: outside.Shape) -> float:
        return information(problem, f, inflation) + shape.scanned * math.log(n_eff(problem))

    while subset:
        full = information(problem, fits[subset], inflation)
        smaller = [frozenset(kept) for size in range(len(subset))
                   for kept in itertools.combinations(sorted(subset), size)]
        # after a replacement every smaller subset of what stands was a smaller subset before
        new = [kept for kept in smaller if kept not in scanned]
        shapes = dict(zip(new, pool.run(_competitors, [portable(fits[kept]) for kept in new])))
        tried = [(kept, shape) for kept in new for shape in shapes[kept]]
        scanned.update({kept: [] for kept in new})
        for (kept, shape), f in zip(tried, pool.fit_many([_with_shape(fits[kept], shape) for kept, shape in tried])):
            scanned[kept].append((shape, f))
        scored = sorted(((bic(f, shape), kept, shape) for kept in smaller for shape, f in scanned[kept]),
                        key=lambda b: b[0])
        for m in in_order(subset):
            alternatives = [b for b, kept, _ in scored if m not in kept]
            if alternatives:
                margins[m] = min(alternatives) - full
        best = next(((b, kept, shape) for b, kept, shape in scored if full - b >= MIN_DELTA_BIC), None)
        if best is None:
            break
        replaced_bic, kept, shape = best
        doubtful = in_order(subset - kept)
        beside, *withouts = pool.fit_many([_with_shape(f, shape)
                                           for f in [fits[subset]] + [fits[subset - {m}] for m in doubtful]])
        reference = bic(beside, shape)
        standing = set(kept)
        needed = max(MIN_DELTA_BIC, BESIDE_SHARE * (full - replaced_bic))
        for m, without in zip(doubtful, withouts):   # still needed beside the shape, and of a size that counts?
            size = MECHANISMS[m].size(problem, beside)
            if (bic(without, shape) - reference >= needed and size >= MECHANISMS[m].floor
                    and size >= BESIDE_SIZE_SHARE * MECHANISMS[m].size(problem, fits[subset])):
                standing.add(m)
        if standing == set(subset):
            break   # the shape is needed beside every mechanism: they stand, it is reported
        kind, channel, _ = outside.describe(problem, shape)
        for m in in_order(subset - standing):
            replaced.append(Dropped(m, f"a {kind.replace('_', ' ')} ({channel}) explains the data better in its "
                                       f"place (BIC lower by {full - replaced_bic:.1f})"))
        subset = frozenset(standing)
    return subset, tuple(replaced), {m: v for m, v in margins.items() if m in subset}


def decide(problem: Problem, fits: dict, subset: frozenset, inflation, workers: int | None = None) -> Verdict:
    """Items 2 and 3 of the module; the independent scans and fits in ``workers`` processes
    (:class:`.fitpool.FitPool`, default one per core)."""
    with FitPool(problem, workers) as pool:
        subset, replaced, margins = replace_by_shapes(problem, fits, subset, inflation, pool)
        f = fits[subset]
        found = outside.characterise(problem, f, problem.y - f.model, pool)
    return Verdict(subset, f, tuple(found), replaced, margins)
