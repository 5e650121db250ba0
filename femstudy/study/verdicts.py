"""The failure margins a study quotes, with the verdicts its own verification gave them.

The governing margin is the smallest margin of every near-hole measure — at each distance
from the hole, beside its wall and beyond each exclusion radius, by the stress criteria and the
strain criterion (:meth:`femstudy.hole.study.HoleResult.margins`) — whatever its measure's
verdict. A measure that has not converged is not dropped for it: its margin is quoted with the
uncertainty band the verification measured (:mod:`femstudy.study.verification`), and is "not
established" when no band can be given. The band of a margin m with relative uncertainty u is
[m / (1 + u), m / (1 − u)] (a load factor scales inversely with the stress).
"""

from __future__ import annotations

import math


def _status(verdict) -> str:
    if verdict is None:
        return "not verified"
    if verdict.verdict == "converged":
        return "converged"
    return "band" if all(math.isfinite(x) for x in verdict.band()) else "not established"


def gate(margins: dict, verification) -> dict:
    """``margins`` (:meth:`femstudy.hole.study.HoleResult.margins`) with each row's verdict,
    uncertainty and band from ``verification`` (:class:`~femstudy.study.verification.Verification`,
    or None), and per loading the ``governing`` row: the smallest margin of all."""
    out = dict(margins)
    for loading in ("dynamic", "static"):
        rows = []
        for row in margins.get(loading, []):
            found = None if verification is None else verification.of(row["kind"], row["radius_mm"], "margin",
                                                                         loading)
            u = None if found is None else found.uncertainty
            low, high = (math.nan, math.nan) if found is None else found.band()
            rows.append({**row, "convergence": None if found is None else found.verdict,
                         "uncertainty": u, "band": [low, high], "status": _status(found)})
        out[loading] = rows
        usable = [r for r in rows if math.isfinite(r["margin"])]
        out[f"governing_{loading}"] = min(usable, key=lambda r: r["margin"]) if usable else None
    return out
