"""Failure margins only from converged hole measures (femstudy/study/verdicts.py)."""

import json

import pytest

from femstudy.casefile import load_case, parse_case
from femstudy.errors import UserError
from femstudy.study import verdicts
from femstudy.convergence import assess

CASE = parse_case("name = 't'\n[mesh]\nsize_mm = 8.0\nsite_size_mm = 1.0\norder = 2\n")
MARGINS = {"basis": "hole", "criterion": "Tsai-Wu", "source": "docs/failure.md",
           "dynamic": [{"kind": "distance", "radius_mm": 0.5, "strength_ratio": 4.0, "station": 1, "tip_depth_mm": 2.0},
                       {"kind": "distance", "radius_mm": 1.0, "strength_ratio": 9.0, "station": 1, "tip_depth_mm": 2.0}],
           "static": [{"kind": "distance", "radius_mm": 1.0, "strength_ratio": 12.0, "station": 1, "tip_depth_mm": 2.0}]}


def record(conditions: dict) -> dict:
    return {"conditions": conditions, "measures": [
        {"kind": "distance", "radius_mm": 0.5, "verdict": "not converging", "gci_fine": None},
        {"kind": "distance", "radius_mm": 1.0, "verdict": "converged", "gci_fine": 0.01}]}


def test_the_governing_margin_is_the_smallest_among_converged_measures_only():
    gated = verdicts.gate(MARGINS, verdicts.applicable(record(verdicts.conditions(CASE)), verdicts.conditions(CASE)))
    assert [r["convergence"] for r in gated["dynamic"]] == ["not converging", "converged"]
    assert gated["governing_dynamic"]["strength_ratio"] == 9.0  # not the 4.0 of the unconverged 0.5 mm measure
    assert gated["governing_static"]["strength_ratio"] == 12.0


def test_a_record_made_under_other_conditions_admits_no_margin():
    other = {**verdicts.conditions(CASE), "mesh_size_mm": 16.0}
    gated = verdicts.gate(MARGINS, verdicts.applicable(record(other), verdicts.conditions(CASE)))
    assert {r["convergence"] for r in gated["dynamic"]} == {"not assessed"}
    assert gated["governing_dynamic"] is None
    assert "mesh_size_mm (16.0 against 8.0)" in gated["convergence_source"]
    assert verdicts.gate(MARGINS, verdicts.applicable(None, verdicts.conditions(CASE)))["governing_dynamic"] is None


def test_a_coarser_level_inherits_the_fine_verdict_scaled_by_r_to_the_p():
    h = (0.2, 0.3, 0.45)
    small = assess("s", h, [10.0 + 2.0 * x ** 2 for x in h], formal_order=2.0)  # exact order 2
    verdict, gci = verdicts.at_level(small, 0.3)
    assert small.verdict == "converged" and verdict == "converged"
    assert gci == pytest.approx(small.gci_fine * 1.5 ** 2, rel=1e-9)
    assert verdicts.at_level(small, 0.45)[1] == pytest.approx(small.gci_fine * 2.25 ** 2, rel=1e-9)
    large = assess("l", h, [10.0 + 6.0 * x ** 2 for x in h], formal_order=2.0)  # fine GCI 2.9 %, middle 6.6 %
    assert large.verdict == "converged" and large.gci_fine < 0.05
    assert verdicts.at_level(large, 0.3)[0] == "converging"
    assert verdicts.at_level(large, 0.2)[0] == "converged"
    assert verdicts.at_level(assess("o", h, [10.0, 11.0, 10.0], formal_order=2.0), 0.3)[1] is None


def test_bad_records_are_one_clear_error(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(UserError, match="not readable JSON"):
        verdicts.read_record(bad)
    bad.write_text(json.dumps({"measures": [{"kind": "distance"}]}))
    with pytest.raises(UserError, match="not a hole-convergence record"):
        verdicts.read_record(bad)
    case = tmp_path / "c.toml"
    case.write_text('[loads]\nconvergence = "missing.json"\n')
    with pytest.raises(UserError, match="loads.convergence: .*missing.json does not exist"):
        load_case(case)
