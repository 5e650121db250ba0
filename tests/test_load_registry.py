"""Load models are registered where they are defined (femstudy/drilling/registry.py); a case
chooses its load model by name, and the study, the hole models' station loads and the
command line follow it."""

import numpy as np
import pytest

from femstudy.casefile import parse_case
from femstudy.drilling import DrillingConditions, evaluate, load_parts, registry
from femstudy.drilling.registry import LoadModel, LoadParts
from femstudy.errors import UserError
from femstudy.study.loading import case_loading


def _constant_parts(cond, t_s, depth_mm, content):
    """A toy model: 10 N and 20 N·mm of cutting while the tip is in the cortex, 5 N·mm of evacuation torque."""
    inside = ((depth_mm > 0) & (depth_mm <= cond.cortex_mm)).astype(float)
    return LoadParts(10.0 * inside, 20.0 * inside, 0.0 * inside, 5.0 * inside)


@pytest.fixture(scope="module")
def toy_model():
    return registry.register(LoadModel("toy-constant", "a constant toy load", "black", _constant_parts, rank=99))


def test_the_built_in_models_are_registered_in_table_order():
    assert registry.names()[:4] == ("allotta", "clogging", "chi", "peng")
    assert "chi" not in registry.names("study")  # no torque: it cannot load a study
    assert set(registry.names("synthesis")) == {"allotta", "clogging"}


def test_a_registered_model_is_evaluated_and_chosen_by_a_case(toy_model):
    cond = DrillingConditions(2.0, 1500.0, 6.0)
    h = evaluate("toy-constant", cond, [1.0, 4.0])  # tip at 2 mm (in the cortex) and 8 mm (beyond)
    np.testing.assert_allclose(h.thrust_N, [10.0, 0.0])
    np.testing.assert_allclose(h.torque_Nmm, [25.0, 0.0])
    case = parse_case('name = "toy"\n[drilling]\nmodel = "toy-constant"\nload_scale = 2.0\n')
    loading = case_loading(case, 6.0)
    assert loading.model == "toy-constant" and loading.title == "a constant toy load"
    assert loading.dynamic.thrust_N.max() == pytest.approx(20.0)  # scaled by load_scale
    station = loading.station(3.0)
    assert (station.cutting_thrust_N, station.cutting_torque_Nmm, station.evacuation_torque_Nmm) == (20.0, 40.0, 10.0)


def test_the_clogging_parts_add_up_to_its_history():
    cond = DrillingConditions(2.0, 1500.0, 6.0)
    t = np.linspace(0.0, 4.0, 41)
    parts, total = load_parts("clogging", cond, t), evaluate("clogging", cond, t)
    np.testing.assert_allclose(parts.thrust_N, total.thrust_N, rtol=1e-15)
    np.testing.assert_allclose(parts.torque_Nmm, total.torque_Nmm, rtol=1e-15)
    assert parts.evacuation_thrust_N.max() > 0 and np.all(load_parts("allotta", cond, t).evacuation_thrust_N == 0)


def test_a_case_naming_an_unknown_model_is_refused_with_its_line():
    with pytest.raises(UserError, match=r"<case>:3: drilling.model.*'pulsed' is not a load model for a study"):
        parse_case('name = "x"\n[drilling]\nmodel = "pulsed"\n')


def test_a_name_is_registered_once(toy_model):
    with pytest.raises(UserError, match="already registered"):
        registry.register(toy_model)
