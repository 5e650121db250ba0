"""Combined load histories: cutting plus chip evacuation, and the literature models."""

import numpy as np
import pytest

from femstudy.drilling import clogging
from femstudy.drilling import registry
from femstudy.drilling.history import DrillingConditions, evaluate, time_grid
from femstudy.drilling.literature import chi_thrust
from femstudy.errors import UserError

COND = DrillingConditions(2.0, 1500, 6.0)


def test_clogging_thrust_in_the_cortex_is_eq_3_16_with_allotta_initial_force():
    t = np.linspace(COND.phase_times()["full engagement"], COND.phase_times()["breakthrough"], 50)
    h = evaluate("clogging", COND, t)
    F0, T0 = COND.static_allotta()
    z = (h.depth_mm - COND.drill.cone_length_mm) / COND.drill.diameter_mm
    mu_f, mu_w = COND.friction
    np.testing.assert_allclose(h.thrust_N, F0 * np.exp(COND.growth_exponent * z), rtol=1e-12)
    np.testing.assert_allclose(h.torque_Nmm, T0 + clogging.torque(z, F0, mu_f, mu_w), rtol=1e-12)


def test_clogging_equals_allotta_before_full_engagement_and_fades_after_breakthrough():
    entry = np.linspace(0, COND.phase_times()["full engagement"], 20)
    np.testing.assert_allclose(evaluate("clogging", COND, entry).thrust_N,
                               evaluate("allotta", COND, entry).thrust_N, rtol=1e-12)
    late = [COND.phase_times()["fully in cancellous"] + 0.1]
    assert evaluate("clogging", COND, late).thrust_N[0] == pytest.approx(
        evaluate("allotta", COND, late).thrust_N[0], rel=1e-12)


@pytest.mark.parametrize("model", ["allotta", "clogging"])
def test_histories_are_continuous(model):
    t = time_grid(COND, 1e-4)
    h = evaluate(model, COND, t)
    scale = np.max(np.abs(h.thrust_N))
    assert np.max(np.abs(np.diff(h.thrust_N))) < 0.01 * scale
    assert np.max(np.abs(np.diff(h.torque_Nmm))) < 0.01 * np.max(np.abs(h.torque_Nmm))


def test_chi_value():
    # Eq 2.24 evaluated by hand: 134.6097 * 1500**-0.3327 * 2**0.5189 * 1.7**1.1841
    assert chi_thrust(2.0, 1500, 1.7) == pytest.approx(31.73, abs=0.01)
    h = evaluate("chi", COND, [1.0])
    assert h.thrust_N[0] == pytest.approx(31.73, abs=0.01) and np.isnan(h.torque_Nmm[0])


def test_peng_thrust_equals_allotta_full_engagement():
    assert evaluate("peng", COND, [1.0]).thrust_N[0] == pytest.approx(COND.static_allotta()[0], rel=1e-12)


def test_time_grid_ends_exactly_at_the_span():
    t = time_grid(COND, 0.1, end_s=3.0)
    assert t[0] == 0 and t[-1] == pytest.approx(3.0) and len(t) == 31
    with pytest.raises(UserError, match="larger than the span"):
        time_grid(COND, 5.0, end_s=3.0)


def test_every_model_evaluates_finite_thrust():
    for model in registry.names():
        assert np.all(np.isfinite(evaluate(model, COND, time_grid(COND, 0.05)).thrust_N))


def test_friction_override_replaces_the_power_law():
    fixed = DrillingConditions(2.0, 1500, 6.0, friction_override=(0.3, 0.7))
    assert fixed.friction == (0.3, 0.7)
    assert fixed.growth_exponent == pytest.approx(clogging.growth_exponent(0.3, 0.7))
    with pytest.raises(UserError):
        DrillingConditions(2.0, 1500, 6.0, friction_override=(0.3, -1.0))
