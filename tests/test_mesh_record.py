"""A sweep's verdicts stored in the cache and picked up by the runs they speak for
(femstudy/study/mesh_convergence.py)."""

import pytest

from femstudy.casefile import parse_case, with_overrides
from femstudy.convergence import assess
from femstudy.study import mesh_convergence

CASE = parse_case('name = "a"\n[mesh]\nsize_mm = 8.0\nsite_size_mm = 1.0\n')
H = (1.0, 1.5, 2.0)  # site sizes of the 8, 12, 16 mm points


def entry(values):
    return assess("max_deflection_mm", H, values, formal_order=3.0).as_dict()


def test_a_run_with_the_same_settings_finds_the_sweep_at_its_own_size(tmp_path):
    values = [0.05 + 0.001 * h ** 3 for h in H]
    mesh_convergence.write_record(CASE, "abc", tmp_path, "P2-site", {"quantities": {"max_deflection_mm": entry(values)}},
                                  [16.0, 12.0, 8.0], "femstudy sweep a.toml --sizes 16,12,8")
    found = mesh_convergence.find(CASE, "abc", tmp_path, 8.0, {"max_deflection_mm": 1.0})
    record = found["quantities"]["max_deflection_mm"]
    a = assess("max_deflection_mm", H, values, formal_order=3.0)
    assert record["verdict"] == a.verdict and record["uncertainty"] == pytest.approx(a.gci_fine)
    coarser = mesh_convergence.find(with_overrides(CASE, {"mesh.size_mm": 12.0, "mesh.site_size_mm": 1.5}), "abc",
                                    tmp_path, 12.0, {"max_deflection_mm": 1.5})
    assert coarser["quantities"]["max_deflection_mm"]["uncertainty"] == pytest.approx(a.gci_fine * 1.5 ** a.order_used)


def test_other_settings_another_surface_or_an_unmeshed_size_find_nothing(tmp_path):
    mesh_convergence.write_record(CASE, "abc", tmp_path, "P2-site", {"quantities": {"max_deflection_mm": entry(
        [0.05, 0.0501, 0.0503])}}, [16.0, 12.0, 8.0], "femstudy sweep a.toml --sizes 16,12,8")
    other = with_overrides(CASE, {"clamps.length_mm": 30.0})
    assert mesh_convergence.find(other, "abc", tmp_path, 8.0, {"max_deflection_mm": 1.0})["quantities"] == {}
    assert mesh_convergence.find(CASE, "xyz", tmp_path, 8.0, {"max_deflection_mm": 1.0})["quantities"] == {}
    unmeshed = mesh_convergence.find(with_overrides(CASE, {"mesh.size_mm": 10.0}), "abc", tmp_path, 10.0,
                                     {"max_deflection_mm": 1.0})
    assert unmeshed["quantities"] == {} and "did not mesh 10 mm" in unmeshed["source"]
