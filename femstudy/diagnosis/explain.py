"""The selected mechanisms in physical terms: parameters with units and a paragraph each (each
mechanism's ``explain``, :mod:`.mechanisms`), and the alignment and calibration beside them."""

from __future__ import annotations

from femstudy.diagnosis.fit import Fit
from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.mechanisms.registry import mechanism, significant as _r
from femstudy.diagnosis.select import Selection, effect_sizes


def alignment(problem: Problem, fit: Fit) -> dict:
    """The nuisance parameters of the aligned simulation (not physics)."""
    out = {"shift_s": round(fit.params["shift_s"], 4)}
    if "stop_depth_mm" in fit.params:
        out["stop_depth_mm"] = round(fit.params["stop_depth_mm"], 3)
    for c in problem.channels:
        out[f"{c}_tare"] = round(fit.params[f"{c}_tare"], 4)
    return out


def calibration(problem: Problem, fit: Fit) -> dict:
    """The scale on each channel's simulated cutting load in the improved fit (1 = as simulated)."""
    return {f"{c}_scale": round(fit.params.get(f"{c}_scale", 1.0), 4) for c in problem.channels}


def mechanisms(problem: Problem, fit: Fit, selection: Selection, verdict, bone_mu_w: float | None) -> list[dict]:
    """The contract's ``missing_physics`` entries for the named subset (``verdict.subset``),
    most confident first; confidence from the verdict (:mod:`.verdict`)."""
    out = []
    sizes = effect_sizes(problem, fit)
    subset = verdict.subset
    for m in sorted(subset, key=lambda m: -verdict.confidence[m]):
        params, text = mechanism(m).explain(problem, fit.params, bone_mu_w)
        delta = selection.bic[subset - {m}] - selection.bic[subset]
        out.append({"mechanism": m, "confidence": verdict.confidence[m], "parameters": params,
                    "explanation": text, "evidence": {"delta_bic": round(delta, 1), "size": _r(sizes[m]),
                                                      "inclusion_probability": round(selection.confidence[m], 4)}})
    return out
