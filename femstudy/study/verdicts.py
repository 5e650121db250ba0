"""Convergence verdicts of the hole measures, and the failure margins they admit.

A margin to failure means something only where the stress behind it has converged. The
verdicts come from a measurement of the hole model's convergence on the same femur, global
mesh and hole refinement as the run — a record written by ``bench/hole_convergence.py --json``
(three hole refinements judged by :func:`femstudy.convergence.assess`, formal order 2,
against the placement noise) — named in the case by ``loads.convergence``. :func:`gate`
marks each margin row with its measure's verdict and quotes as the *governing* margin the
smallest strength ratio among the rows whose verdict is "converged" (GCI ≤ 5 %, or within
the noise); without a record, or one made under other conditions, no margin governs.

The record speaks for one hole refinement, one of its three levels (the case's own, so that
the study runs at the cost of that level; the coarsest in the shipped records): a measure
judged "converged" on the ladder keeps that verdict at that level when its own error
estimate, GCI_fine · (h/h_fine)^p (the error scales as h^p in the asymptotic range, p the
order used), is still at most 5 %, or when all three levels agree within the placement noise
or converge by a shrinking oscillation, whose half range bounds every level (:func:`at_level`).

Record format (JSON): ``{"conditions": {...}, "measures": [{"kind": "distance" | "wall" |
"exclusion", "radius_mm": float, "verdict": str, "reason": str, "gci_fine": float | null,
"values_MPa": [...]}, ...]}``, the conditions being those of :func:`conditions`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from femstudy.errors import UserError
from femstudy.convergence import GCI_CONVERGED

#: Conditions a record must share with the run for its verdicts to apply.
MATCHED = ("surface", "mesh_size_mm", "site_size_mm", "order", "refinement", "submodel_radius_mm", "smoothing_mm")


def conditions(case) -> dict:
    """The conditions of ``case`` that a hole-convergence record is tied to (the hole refinement
    among them: the level the verdicts speak for)."""
    return {"surface": case.geometry.surface, "mesh_size_mm": case.mesh.size_mm,
            "site_size_mm": case.mesh.site_size_mm, "order": case.mesh.order,
            "refinement": case.loads.refinement,
            "submodel_radius_mm": case.loads.submodel_radius_mm, "smoothing_mm": case.loads.smoothing_mm}


def at_level(assessment, h_mm: float) -> tuple[str, float | None]:
    """Verdict and GCI of the level with mesh measure ``h_mm`` among the three behind
    ``assessment`` (:class:`femstudy.convergence.Assessment`; see the module docstring)."""
    if assessment.verdict != "converged":
        return assessment.verdict, None
    if assessment.order_used is None:  # within the noise or oscillatory: the spread is the estimate
        return "converged", assessment.gci_fine
    gci = assessment.gci_fine * (h_mm / min(assessment.h)) ** assessment.order_used
    return ("converged" if gci <= GCI_CONVERGED else "converging"), gci


def read_record(path: Path) -> dict:
    """A hole-convergence record, checked for the keys :func:`gate` needs."""
    try:
        record = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UserError(f"loads.convergence: {path} does not exist (write it with bench/hole_convergence.py --json)") from None
    except (OSError, ValueError) as exc:
        raise UserError(f"loads.convergence: {path} is not readable JSON ({exc})") from None
    measures = record.get("measures") if isinstance(record, dict) else None
    if not (isinstance(record.get("conditions") if isinstance(record, dict) else None, dict)
            and isinstance(measures, list)
            and all(isinstance(m, dict) and {"kind", "radius_mm", "verdict"} <= m.keys() for m in measures)):
        raise UserError(f"loads.convergence: {path} is not a hole-convergence record "
                        "(it needs 'conditions' and 'measures' with kind, radius_mm and verdict)")
    return record


def applicable(record: dict | None, run_conditions: dict) -> dict:
    """The verdicts a run may use: ``{"source": text, "measures": [{"kind", "radius_mm",
    "verdict", "gci_fine"}, ...]}``, empty when there is no record or it was made under other
    conditions (the source then says which)."""
    if record is None:
        return {"source": "not assessed: the case names no hole-convergence record (loads.convergence)", "measures": []}
    differ = [k for k in MATCHED if k in record["conditions"] and record["conditions"][k] != run_conditions.get(k)]
    if differ:
        return {"source": "not assessed: the record was made with other " + ", ".join(
            f"{k} ({record['conditions'][k]} against {run_conditions.get(k)})" for k in differ), "measures": []}
    return {"source": record.get("command", "hole-convergence record"),
            "measures": [{"kind": m["kind"], "radius_mm": float(m["radius_mm"]), "verdict": m["verdict"],
                          "gci_fine": m.get("gci_fine")} for m in record["measures"]]}


def verdict_of(convergence: dict, kind: str, radius_mm: float) -> dict:
    """The entry of :func:`applicable`'s result for one measure ("not assessed" if absent)."""
    for m in convergence["measures"]:
        if m["kind"] == kind and abs(m["radius_mm"] - radius_mm) < 1e-9:
            return m
    return {"kind": kind, "radius_mm": radius_mm, "verdict": "not assessed", "gci_fine": None}


def gate(margins: dict, convergence: dict) -> dict:
    """``margins`` (:meth:`femstudy.hole.study.HoleResult.margins`) with each row's
    ``convergence`` verdict (from :func:`applicable`) and, per loading, the ``governing`` row:
    the smallest strength ratio among converged measures (None when none is)."""
    out = {**margins, "convergence_source": convergence["source"]}
    for loading in ("dynamic", "static"):
        rows = []
        for row in margins.get(loading, []):
            found = verdict_of(convergence, row["kind"], float(row["radius_mm"]))
            rows.append({**row, "convergence": found["verdict"], "gci_fine": found["gci_fine"]})
        out[loading] = rows
        usable = [r for r in rows if r["convergence"] == "converged" and math.isfinite(r["strength_ratio"])]
        out[f"governing_{loading}"] = min(usable, key=lambda r: r["strength_ratio"]) if usable else None
    return out
