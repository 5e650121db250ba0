"""The near-hole outputs of one sample, read from the public :class:`~femstudy.hole.study.HoleResult`.

This is the one place that reads hole results, so a change of what the study calls its
governing margin changes this file only. Per sample: the headline von Mises stress (the largest
over the stations at the case's headline distance from the hole, dynamic loading), the largest
von Mises outside the quoted exclusion radius, and the governing margin — the smallest strength
ratio among the measures the case's convergence record admits (:func:`femstudy.study.verdicts.gate`),
or among every measure when no record applies (``margin_basis`` says which).
"""

from __future__ import annotations

import math

from femstudy.study import verdicts

#: Output columns this module fills, with their units.
COLUMNS = ("hole_von_mises_MPa", "hole_exclusion_von_mises_MPa", "governing_margin")


def hole_outputs(hole, convergence: dict) -> tuple[dict, str]:
    """The sample's near-hole outputs (:data:`COLUMNS`) and the basis of its margin."""
    headline = hole.headline("dynamic").von_mises_MPa
    excluded = hole.worst("exclusion", hole.options.exclusion_radius_mm, "dynamic").von_mises_MPa
    gated = verdicts.gate(hole.margins(), convergence)
    governing = gated.get("governing_dynamic")
    if governing is not None:
        margin, basis = governing["strength_ratio"], "converged measures"
    else:
        ratios = [r["strength_ratio"] for r in gated.get("dynamic", []) if math.isfinite(r["strength_ratio"])]
        margin, basis = (min(ratios) if ratios else math.nan), "every measure (none judged converged)"
    return {"hole_von_mises_MPa": float(headline), "hole_exclusion_von_mises_MPa": float(excluded),
            "governing_margin": float(margin)}, basis
