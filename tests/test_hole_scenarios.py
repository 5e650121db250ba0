"""Alternatives measured on the study's own local meshes (femstudy.hole.study.HoleScenario), as
the sensitivity table uses them, give what a hole model built for each alternative alone gives."""

from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest

from femstudy.casefile import parse_case, with_overrides
from femstudy.hole.study import HoleScenario, hole_site, hole_stresses
from femstudy.study.global_model import prepare
from femstudy.study.loading import case_loading

CASE = """
name = "scenarios"
[mesh]
size_mm = 16.0
[loads]
application = "hole"
stations = 2
refinement = 0.5
distances_mm = [1.0, 2.0]
exclusion_radii_mm = [1.0]
"""


@lru_cache(maxsize=None)
def _model(cache):
    case = parse_case(CASE)
    model = prepare(case, cache)
    fs = model.factorize()
    fields = fs.bc.expand(fs.factor.solve(model.patch.patterns[fs.bc.free]))
    loading = case_loading(case, model.femur.site.cortical_thickness_mm, None, model.femur.site.beyond_cortex)
    inputs = loading.hole_inputs(case.materials.to_fe(), case.mesh.order, case.clamps.length_mm)
    return case, model, fields, inputs


@pytest.fixture(scope="module")
def built(mesh_cache):
    return _model(mesh_cache)


def dynamic(measures):
    """The dynamic loading's von Mises stress and load factors of every measure."""
    return {(m.kind, m.radius_mm, q): getattr(m, q) for m in measures if m.loading == "dynamic"
            for q in ("von_mises_MPa", "strength_ratio", "strain_ratio")}


def test_each_alternative_equals_its_own_hole_model(built):
    case, model, fields, inputs = built
    options = case.loads.hole_options()
    site = hole_site(inputs, model.femur, options)
    other = with_overrides(case, {"materials.cortical_model": "transversely_isotropic"}, what="test").materials.to_fe()
    field = 1.7 * fields  # another global model's unit fields
    scenarios = (HoleScenario("field", unit_fields=field), HoleScenario("materials", materials=other),
                 HoleScenario("cone", cone_traction="uniform"),
                 HoleScenario("all", unit_fields=field, materials=other, cone_traction="uniform"))
    shared = hole_stresses(inputs, model.femur, model.system, fields, options, site=site, stations=(-1,),
                           scenarios=scenarios)
    alone = {"field": hole_stresses(inputs, model.femur, model.system, field, options, site=site, stations=(-1,)),
             "materials": hole_stresses(replace(inputs, materials=other), model.femur, model.system, fields, options,
                                        site=site, stations=(-1,)),
             "cone": hole_stresses(inputs, model.femur, model.system, fields, options,
                                   site=replace(site, options=replace(site.options, cone_traction="uniform")),
                                   stations=(-1,)),
             "all": hole_stresses(replace(inputs, materials=other), model.femur, model.system, field, options,
                                  site=replace(site, options=replace(site.options, cone_traction="uniform")),
                                  stations=(-1,))}
    base = dynamic(shared.measures)
    assert dynamic(hole_stresses(inputs, model.femur, model.system, fields, options, site=site,
                                 stations=(-1,)).measures) == pytest.approx(base, rel=1e-9)
    for name, result in alone.items():
        got, want = dynamic(shared.scenarios[name]), dynamic(result.measures)
        assert set(got) == set(want) and len(got) == 15  # 2 distances, 2 walls, 1 exclusion radius
        assert got == pytest.approx(want, rel=1e-8), name
        assert got != pytest.approx(base, rel=1e-3), name  # each alternative moves the answers
    assert all(m.station == 1 for m in shared.scenarios["all"])  # the deepest of two stations


def test_a_longer_clamp_is_left_out_of_the_exclusion_measures(built):
    """A clamp reaching past the whole femur leaves no exclusion point; the distance measures stay."""
    case, model, fields, inputs = built
    options = case.loads.hole_options()
    shared = hole_stresses(inputs, model.femur, model.system, fields, options, stations=(-1,),
                           scenarios=(HoleScenario("clamped", clamp_length_mm=1e4),))
    measures = {(m.kind, m.radius_mm): m for m in shared.scenarios["clamped"]}
    assert measures[("exclusion", 1.0)].points == 0 and np.isnan(measures[("exclusion", 1.0)].von_mises_MPa)
    assert measures[("distance", 1.0)].von_mises_MPa == pytest.approx(
        dynamic(shared.measures)[("distance", 1.0, "von_mises_MPa")], rel=1e-12)
