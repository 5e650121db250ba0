"""Every subset of the catalogue fitted, each mechanism in its best variant.

1. The mechanisms whose variants are fixed alternatives (a drift's polynomial degree, a monotone
   spline's number of intervals; listed simplest first) are fitted together, each in its richest
   variant; then each mechanism's other variants in turn, the rest left richest. Per mechanism the
   variant of the lowest BIC and its simplest variant stay candidates. A variant that reads the
   simulated chip friction as staying after breakthrough (:data:`.catalogue.FRICTION_STAYS`) is
   left out of this step (beside a clogging the friction is read as fading whatever the variant
   says, :func:`.model.friction_stays`) and is a candidate as offered.
2. A mechanism whose variants come from a scan (a feed pulsation's frequency) scans the residual
   of that fit and of the simulation alone; the distinct frequencies found, at most
   :data:`MAX_SCANNED` of them, are its candidates, with the slower waves whose harmonic the best
   line may be (:func:`_distinct`): each is fitted beside the best fit of step 1, and of those
   whose fundamental is their largest line (:func:`.catalogue.feed_pulsation.slower_wave_holds`)
   the one of the lowest BIC stays a candidate.
3. Every subset (2⁴ = 16 with the four mechanisms) is fitted in every combination of its members'
   candidates that is a distinct model, each started from the best fit of the subsets one
   mechanism smaller (with the friction read as fading, from the best such fit: the staying reading
   adds fits and changes none of the others); the combination with the lowest BIC (on the data's
   own noise level) is the subset's fit, a slower wave only where its fundamental is its largest
   line (:func:`_better`).
"""

from __future__ import annotations

import itertools
import math

from femstudy.diagnosis.catalogue import FRICTION_STAYS, MECHANISMS, Variant, in_order
from femstudy.diagnosis.catalogue.feed_pulsation import FUNDAMENTAL_OF, slower_wave_holds
from femstudy.diagnosis.fit import Fit, fit
from femstudy.diagnosis.fitpool import FitPool, portable, restored
from femstudy.diagnosis.model import Spec, friction_stays
from femstudy.diagnosis.problem import Problem

#: Most scanned variants (frequencies) tried per mechanism.
MAX_SCANNED = 4
#: Two scanned frequencies closer than this (relative) are one.
SAME_FREQUENCY = 0.03


def bic(problem: Problem, f: Fit) -> float:
    """χ² + k ln n on the data's own noise level."""
    return f.chi2_total * problem.n_eff_factor + f.n_params * math.log(max(problem.n * problem.n_eff_factor, 3))


def _start(fits: dict, subset: frozenset) -> dict:
    smaller = [fits[subset - {m}] for m in in_order(subset) if subset - {m} in fits]
    return min(smaller, key=lambda f: f.chi2_total).params() if smaller else {}


def _distinct(variants: list[Variant]) -> list[Variant]:
    """The first :data:`MAX_SCANNED` distinct scanned variants, then the slower waves found as
    harmonics of a line (:data:`.catalogue.feed_pulsation.FUNDAMENTAL_OF`) that are distinct from
    them: those only add candidates."""
    def distinct(candidates: list[Variant], kept: list[Variant]) -> list[Variant]:
        out: list[Variant] = []
        for v in candidates:
            f = v.get("frequency_hz")
            if f is None or all(abs(f / o.get("frequency_hz") - 1) > SAME_FREQUENCY
                                or v.get("harmonics") != o.get("harmonics") for o in kept + out):
                out.append(v)
        return out

    lines = distinct([v for v in variants if v.get(FUNDAMENTAL_OF) is None], [])[:MAX_SCANNED]
    slower = distinct([v for v in variants if v.get(FUNDAMENTAL_OF) is not None], lines)
    return lines + slower


def _model_key(spec: Spec) -> tuple:
    """What makes ``spec``'s model: its variants' settings, without a chip friction read as
    staying where the model reads it as fading anyway (:func:`.model.friction_stays`)."""
    stays = friction_stays(spec)
    return tuple((name, tuple(kv for kv in v.settings if stays or kv[0] != FRICTION_STAYS))
                 for name, v in spec.variants)


def _distinct_models(specs: list[Spec]) -> list[Spec]:
    """``specs`` without those that are the same model as an earlier one (:func:`_model_key`)."""
    seen, out = set(), []
    for spec in specs:
        key = _model_key(spec)
        if key not in seen:
            seen.add(key)
            out.append(spec)
    return out


def candidates(problem: Problem, baseline: Fit, pool: FitPool | None = None) -> dict[str, list[Variant]]:
    """Each available mechanism's candidate variants (items 1 and 2 of the module docstring)."""
    pool = FitPool(problem, workers=1) if pool is None else pool
    available = [m for m in MECHANISMS.values() if m.available(problem)]
    fixed = [m for m in available if not m.scans]
    offered = {m.name: m.variants(problem, None, None) for m in fixed}
    options = {name: [v for v in variants if not v.get(FRICTION_STAYS)] for name, variants in offered.items()}
    staying = {name: [v for v in variants if v.get(FRICTION_STAYS)] for name, variants in offered.items()}
    richest = {m.name: options[m.name][-1] for m in fixed}

    def together(choice: dict) -> Spec:
        return Spec(tuple((m.name, choice[m.name]) for m in fixed))

    alternatives = [together({**richest, m.name: variant}) for m in fixed for variant in options[m.name][:-1]]
    fitted = pool.fit_many([(spec, None) for spec in [together(richest)] + alternatives] if fixed else [])
    full = best = fitted[0] if fixed else None
    fitted_alternatives = iter(fitted[1:])   # in the order of ``alternatives``
    out = {}
    for m in fixed:
        chosen, chosen_bic = richest[m.name], bic(problem, full)
        for variant in options[m.name][:-1]:
            f = next(fitted_alternatives)
            if bic(problem, f) < chosen_bic:
                chosen, chosen_bic = variant, bic(problem, f)
            if bic(problem, f) < bic(problem, best):
                best = f
        out[m.name] = [chosen] + ([options[m.name][0]] if options[m.name][0] != chosen else []) + staying[m.name]
    scanning = [m.name for m in available if m.scans]
    bases = [portable(base) for base in ([best] if best is not None else []) + [baseline]]
    found = iter(pool.run(_scanned, [(name, base) for name in scanning for base in bases]))
    for name in scanning:
        out[name] = _one_slower_wave(problem, pool, best, name,
                                     _distinct([variant for _ in bases for variant in next(found)]))
    return {name: variants for name, variants in out.items() if variants}


def _one_slower_wave(problem: Problem, pool: FitPool, best: Fit | None, name: str, variants: list[Variant]) -> list[Variant]:
    """``variants`` of the scanning mechanism ``name`` with one slower wave at most: each is fitted
    beside ``best`` (the fixed mechanisms' best fit), and of those whose fundamental is their
    largest line (:func:`.catalogue.feed_pulsation.slower_wave_holds`) the one of the lowest BIC
    stays (item 2 of the module docstring)."""
    slower = [v for v in variants if v.get(FUNDAMENTAL_OF) is not None]
    beside = best.spec.variants if best is not None else ()
    fits = pool.fit_many([(Spec(beside + ((name, v),)), best.params() if best is not None else None) for v in slower])
    held = [(bic(problem, f), k) for k, f in enumerate(fits) if slower_wave_holds(f)]
    kept = slower[min(held)[1]] if held else None
    return [v for v in variants if v.get(FUNDAMENTAL_OF) is None or v is kept]


def _scanned(problem: Problem, item: tuple[str, tuple]) -> list[Variant]:
    """A scanning mechanism's variants found in the residual of a fit sent as
    :func:`.fitpool.portable` (item 2 of the module docstring)."""
    name, sent = item
    base = restored(problem, sent)
    return MECHANISMS[name].variants(problem, problem.y - base.model, base.evaluation)


def fit_all(problem: Problem, baseline: Fit, workers: int | None = None) -> dict[frozenset, Fit]:
    """The best fit of every subset (item 3 of the module docstring), by frozenset of names;
    ``workers``: processes the independent fits are spread over (default: one per core)."""
    with FitPool(problem, workers) as pool:
        options = candidates(problem, baseline, pool)
        names = list(options)
        fits: dict[frozenset, Fit] = {frozenset(): baseline_fit(problem)}
        fading = dict(fits)   # the best fits with the simulated chip friction read as fading
        for size in range(1, len(names) + 1):
            tasks = []
            for subset in itertools.combinations(names, size):
                specs = [Spec(tuple(zip(subset, combo))) for combo in itertools.product(*(options[n] for n in subset))]
                for spec in _distinct_models(specs):
                    stays = friction_stays(spec)
                    tasks.append((frozenset(subset), spec, (fits,) if stays else (fits, fading),
                                  _start(fits if stays else fading, frozenset(subset))))
            fitted = pool.fit_many([(spec, start) for _, spec, _, start in tasks])
            for (subset, _, kept_in, _), f in zip(tasks, fitted):   # the first of equal BICs, as one by one
                for kept in kept_in:
                    if subset not in kept or _better(problem, f, kept[subset]):
                        kept[subset] = f
    return fits


def refit(problem: Problem, f: Fit) -> Fit:
    """``f``'s model fitted again on ``problem``, in the same variants and from ``f``'s optimum
    (what :func:`refit_all` does for each subset)."""
    return fit(problem, f.spec, f.params())


def refit_all(problem: Problem, fits: dict[frozenset, Fit], workers: int | None = None,
              refitted: dict[frozenset, Fit] | None = None) -> dict[frozenset, Fit]:
    """Each subset's fit of an earlier search (``fits``) fitted again on ``problem``, in the same
    variants and from its optimum: the search of a problem a few percent from the one it ran on
    (the calibration scales of :mod:`.diagnose`), at one fit per subset; those in ``refitted``
    (this function's own answers for some of the subsets) are kept, not fitted again."""
    done = dict(refitted or {})
    todo = [s for s in fits if s not in done]
    with FitPool(problem, workers) as pool:
        done.update(zip(todo, pool.fit_many([(fits[s].spec, fits[s].params()) for s in todo])))
    return {s: done[s] for s in fits}


def _better(problem: Problem, f: Fit, than: Fit) -> bool:
    """Whether ``f`` is a better fit of its subset than ``than``: a lower BIC, and before that
    the form it was offered as (a slower wave whose fundamental is not its largest line is not
    that wave: :func:`.catalogue.feed_pulsation.slower_wave_holds`)."""
    holds, other_holds = slower_wave_holds(f), slower_wave_holds(than)
    if holds != other_holds:
        return holds
    return bic(problem, f) < bic(problem, than)


def baseline_fit(problem: Problem) -> Fit:
    """The empty model fitted: the simulation with the alignment refined and the tares."""
    return fit(problem, Spec())
