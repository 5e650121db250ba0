"""The near-hole outputs of one sample, read from the public :class:`~femstudy.hole.study.HoleResult`.

This is the one place that reads hole results, so a change of what the study calls its
governing margin changes this file only. Per sample: the headline von Mises stress (the largest
over the stations at the case's headline distance from the hole, dynamic loading), the largest
von Mises outside the quoted exclusion radius, and the governing margin as the study defines it
(:func:`femstudy.study.verdicts.gate`): the smallest margin of every measure, by the stress and
strain criteria, none dropped. The samples are not verified one by one (three more refinements
and placements each); the nominal run's verification (``femstudy run``) gives the band.
"""

from __future__ import annotations

import math

from femstudy.study import verdicts

#: Output columns this module fills, with their units.
COLUMNS = ("hole_von_mises_MPa", "hole_exclusion_von_mises_MPa", "governing_margin")

#: What the governing margin of a sample is taken over (report.md and uncertainty.json).
MARGIN_BASIS = "every near-hole measure, stress and strain criteria (the nominal run's verification gives its band)"


def hole_outputs(hole) -> tuple[dict, str]:
    """The sample's near-hole outputs (:data:`COLUMNS`) and the basis of its margin."""
    headline = hole.headline("dynamic").von_mises_MPa
    excluded = hole.worst("exclusion", hole.options.exclusion_radius_mm, "dynamic").von_mises_MPa
    governing = verdicts.gate(hole.margins(), None).get("governing_dynamic")
    margin = math.nan if governing is None else governing["margin"]
    return {"hole_von_mises_MPa": float(headline), "hole_exclusion_von_mises_MPa": float(excluded),
            "governing_margin": float(margin)}, MARGIN_BASIS
