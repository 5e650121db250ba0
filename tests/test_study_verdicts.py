"""Verification of the near-hole measures in the run and the margins it admits
(femstudy/study/verification.py, femstudy/study/verdicts.py)."""

import math
from dataclasses import dataclass, field

import pytest

from femstudy.convergence import assess
from femstudy.study import verdicts, verification

H = (0.5625, 0.45, 0.36)  # wall elements of refinements 8/15, 2/3, 5/6 [mm]


def verdict(values, replicates=(), quantity="von_mises_MPa", loading="dynamic", kind="distance", radius=1.0):
    noise = (max(replicates) - min(replicates)) / (sum(replicates) / len(replicates)) if replicates else 0.0
    return verification.Verdict(kind, radius, quantity, loading, H, tuple(values), tuple(replicates), noise,
                                assess("m", H, values, 2.0, noise=noise))


def test_a_monotone_measure_of_order_two_is_judged_at_the_quoted_middle_level():
    """Values 10 + c h² (exact order 2): converged, with GCI_fine carried to the middle level as
    GCI_fine (h_middle / h_fine)^2."""
    v = verdict([10.0 + 2.0 * h ** 2 for h in H])
    assert v.assessment.verdict == "converged" and v.verdict == "converged"
    assert v.quoted == pytest.approx(10.0 + 2.0 * 0.45 ** 2)
    assert v.uncertainty == pytest.approx(v.assessment.gci_fine * (0.45 / 0.36) ** 2, rel=1e-12)
    low, high = v.band()
    assert low < v.quoted < high and (high - v.quoted) / v.quoted == pytest.approx(v.uncertainty)


def test_a_fine_gci_under_five_percent_can_still_be_converging_at_the_quoted_level():
    v = verdict([10.0 + 2.5 * h ** 2 for h in H])
    assert v.assessment.gci_fine < 0.05 < v.uncertainty
    assert v.assessment.verdict == "converged" and v.verdict == "converging"


def test_changes_within_the_replicates_noise_are_converged_with_the_noise_as_band():
    v = verdict([6.05, 6.10, 6.02], replicates=(6.0, 6.2, 6.1))
    assert v.verdict == "converged" and v.assessment.observed_order is None
    assert v.uncertainty == pytest.approx(v.noise)


def test_a_measure_that_does_not_converge_carries_the_spread_of_its_levels_and_replicates():
    v = verdict([5.0, 6.0, 4.8], replicates=(5.0, 5.01, 4.99))  # the swing grows under refinement
    assert v.verdict == "not converging"
    assert v.uncertainty == pytest.approx((6.0 - 4.8) / 6.0)


def test_a_margin_band_scales_inversely():
    v = verdict([4.0, 4.0 * 1.0001, 4.0 * 1.0002], replicates=(3.9, 4.0, 4.1), quantity="margin")
    low, high = v.band()
    u = v.uncertainty
    assert (low, high) == (pytest.approx(v.quoted / (1 + u)), pytest.approx(v.quoted / (1 - u)))


@dataclass
class FakeVerification:
    found: dict = field(default_factory=dict)

    def of(self, kind, radius_mm, quantity="von_mises_MPa", loading="dynamic"):
        return self.found.get((kind, radius_mm, quantity, loading))


MARGINS = {"basis": "hole", "criterion": "Tsai-Wu", "strain_limits": "strain", "source": "docs/failure.md",
           "dynamic": [{"kind": "distance", "radius_mm": 0.5, "margin": 4.0, "strength_ratio": 4.0, "strain_ratio": 9.0,
                        "governed_by": "stress", "station": 2, "tip_depth_mm": 5.5},
                       {"kind": "distance", "radius_mm": 1.0, "margin": 9.0, "strength_ratio": 9.0, "strain_ratio": 20.0,
                        "governed_by": "stress", "station": 2, "tip_depth_mm": 5.5}],
           "static": [{"kind": "distance", "radius_mm": 1.0, "margin": 12.0, "strength_ratio": 12.0, "strain_ratio": 30.0,
                       "governed_by": "stress", "station": 2, "tip_depth_mm": 5.5}]}


def test_the_governing_margin_is_the_smallest_of_all_measures_even_unconverged_with_its_band():
    """Not the 9.0 of the converged 1 mm measure: the 4.0 of the 0.5 mm one, quoted with the band
    its verification measured."""
    found = {("distance", 0.5, "margin", "dynamic"): verdict([3.0, 4.0, 2.8], (3.9, 4.0, 4.1), "margin", radius=0.5),
             ("distance", 1.0, "margin", "dynamic"): verdict([9.0, 9.0 * 1.0001, 9.0 * 1.0002], (8.9, 9.0, 9.1),
                                                             "margin")}
    gated = verdicts.gate(MARGINS, FakeVerification(found))
    governing = gated["governing_dynamic"]
    assert governing["margin"] == 4.0 and governing["convergence"] == "not converging"
    assert governing["status"] == "band" and governing["band"][0] < 4.0 < governing["band"][1]
    assert gated["governing_static"]["margin"] == 12.0 and gated["governing_static"]["status"] == "not verified"


def test_without_verification_every_row_says_so_and_the_smallest_margin_still_governs():
    gated = verdicts.gate(MARGINS, None)
    assert {r["status"] for r in gated["dynamic"]} == {"not verified"}
    assert gated["governing_dynamic"]["margin"] == 4.0
    assert all(math.isnan(x) for x in gated["governing_dynamic"]["band"])


def test_the_ladder_puts_the_case_level_in_the_middle():
    assert verification.ladder(2 / 3) == pytest.approx((2 / 3 / 1.25, 2 / 3, 2 / 3 * 1.25))
