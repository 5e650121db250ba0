"""The selected mechanisms in physical terms: parameters with units and a paragraph each (each
mechanism's ``explain``, :mod:`.mechanisms`)."""

from __future__ import annotations

from femstudy.diagnosis.findings import Evidence, NamedMechanism
from femstudy.diagnosis.fit import Fit
from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.mechanisms.registry import in_order, mechanism, significant as _r
from femstudy.diagnosis.select import Selection, effect_sizes
from femstudy.diagnosis.verdict import Verdict


def mechanisms(problem: Problem, fit: Fit, selection: Selection, verdict: Verdict,
               bone_mu_w: float | None) -> tuple[NamedMechanism, ...]:
    """The named mechanisms of the subset ``verdict.subset`` (the contract's ``missing_physics``),
    most confident first; confidence from the verdict (:mod:`.verdict`)."""
    out = []
    sizes = effect_sizes(problem, fit)
    subset = verdict.subset
    for m in sorted(in_order(subset), key=lambda m: -verdict.confidence[m]):
        params, text = mechanism(m).explain(problem, fit.params, bone_mu_w)
        delta = selection.bic[subset - {m}] - selection.bic[subset]
        out.append(NamedMechanism(m, verdict.confidence[m], params, text,
                                  Evidence(round(delta, 1), _r(sizes[m]), round(selection.confidence[m], 4))))
    return tuple(out)
