"""Unit drill loads on the hole: exact resultants for P1 and P2 at several stations, and the
depth distribution of the chip-evacuation loads."""

import numpy as np
import pytest

from hole_cases import CONE, RADIUS, station_system
from femstudy.errors import UserError
from femstudy.hole import hole_loads

THICKNESS = 5.0
TIPS = (0.9, 2.5, 4.0, 8.0)  # entering, full engagement (two depths), drilled through
P = 0.47  # growth exponent of the thesis's Appendix B mean
#: 1e-9 of the unit resultants: exact up to round-off by construction.
TOL = 1e-9


def resultants(system, f, origin=np.zeros(3)):
    forces = f.reshape(-1, 3)
    return forces.sum(axis=0), np.cross(system.nodes - origin, forces).sum(axis=0)


@pytest.fixture(scope="module", params=[(o, k) for o in (2, 1) for k in range(len(TIPS))],
                ids=[f"P{o}-station{k}" for o in (2, 1) for k in range(len(TIPS))])
def loaded(request):
    order, k = request.param
    station, system = station_system(THICKNESS, TIPS, k, order)
    return station, system, hole_loads(system, station, growth_exponent=P)


def test_cutting_loads_are_a_unit_thrust_and_a_pure_unit_torque(loaded):
    station, system, loads = loaded
    d = loads.axis
    if loads.bottom_area_mm2 == 0:  # drilled through: no cone to cut
        assert station.tip_depth_mm - CONE >= THICKNESS
        assert not loads.cutting_thrust.any() and not loads.cutting_torque.any()
        return
    force, moment = resultants(system, loads.cutting_thrust)
    np.testing.assert_allclose(force, d, atol=TOL)
    np.testing.assert_allclose(moment, 0.0, atol=TOL * RADIUS)  # on the axis by symmetry
    force, moment = resultants(system, loads.cutting_torque)
    np.testing.assert_allclose(force, 0.0, atol=TOL / RADIUS)
    np.testing.assert_allclose(moment, d, atol=TOL)
    # only cone nodes are loaded
    loaded_nodes = np.unique(np.flatnonzero(loads.cutting_thrust) // 3)
    local = station.hole.frame.to_local(system.nodes[loaded_nodes])
    assert np.hypot(local[:, 0], local[:, 1]).max() <= RADIUS * (1 + 1e-12)


def test_evacuation_torque_is_a_unit_moment_on_the_engaged_wall(loaded):
    station, system, loads = loaded
    engaged = min(station.corner_depth_mm, THICKNESS)
    assert loads.engaged_length_mm == pytest.approx(max(engaged, 0.0), abs=1e-12)
    if engaged <= 0:
        assert loads.wall_area_mm2 == 0 and not loads.evacuation_torque.any()
        return
    force, moment = resultants(system, loads.evacuation_torque)
    np.testing.assert_allclose(force, 0.0, atol=TOL / RADIUS)
    np.testing.assert_allclose(moment, loads.axis, atol=TOL)


def test_evacuation_thrust_on_the_bottom_or_on_the_wall(loaded):
    station, system, loads = loaded
    if loads.bottom_area_mm2 > 0:
        np.testing.assert_array_equal(loads.evacuation_thrust, loads.cutting_thrust)
    on_wall = hole_loads(system, station, growth_exponent=P, evacuation_thrust_on="wall")
    if on_wall.wall_area_mm2 > 0:
        force, moment = resultants(system, on_wall.evacuation_thrust)
        np.testing.assert_allclose(force, loads.axis, atol=TOL)
        np.testing.assert_allclose(moment, 0.0, atol=TOL * RADIUS)
    np.testing.assert_array_equal(on_wall.cutting_thrust, loads.cutting_thrust)


def test_bottom_mean_averages_the_cone(loaded):
    _, system, loads = loaded
    if loads.bottom_area_mm2 == 0:
        return
    translation = np.tile([0.1, -0.2, 0.3], len(system.nodes))
    np.testing.assert_allclose(loads.bottom_mean @ translation, [0.1, -0.2, 0.3], rtol=1e-12)
    # a field growing linearly with depth averages to its value at the cone's centroid depth
    linear = np.zeros((len(system.nodes), 3))
    linear[:, 2] = system.nodes @ loads.axis
    assert (loads.bottom_mean @ linear.ravel())[2] == pytest.approx(loads.bottom_centre @ loads.axis, rel=1e-12)


@pytest.mark.parametrize("p", [0.0, P, -0.8])
def test_evacuation_density_grows_as_exp_p_depth_over_diameter(p):
    """The virtual work of the evacuation torque on v = ζ d × (x − o) (ζ the depth, a P2
    field) is the exp(p ζ / D)-weighted mean depth of the engaged wall,
    ∫₀^L ζ e^{pζ/D} dζ / ∫₀^L e^{pζ/D} dζ: the wall is a prism, so the angular factor cancels."""
    station, system = station_system(THICKNESS, TIPS, 2, 2)
    loads = hole_loads(system, station, growth_exponent=p)
    x = system.nodes
    zeta = x @ loads.axis
    v = zeta[:, None] * np.cross(loads.axis, x)
    L, D = loads.engaged_length_mm, 2 * RADIUS
    z = np.linspace(0, L, 20001)
    weight = np.exp(p * z / D)
    expected = np.trapezoid(z * weight, z) / np.trapezoid(weight, z)
    assert loads.evacuation_torque @ v.ravel() == pytest.approx(expected, rel=1e-7)
    thrust_on_wall = hole_loads(system, station, growth_exponent=p, evacuation_thrust_on="wall").evacuation_thrust
    w = np.zeros_like(x)
    w[:, 2] = zeta
    assert thrust_on_wall @ w.ravel() == pytest.approx(expected, rel=1e-7)


def test_force_combines_the_patterns():
    station, system = station_system(THICKNESS, TIPS, 1, 1)
    loads = hole_loads(system, station)
    f = loads.force(20.0, 15.0, 4.0, 3.0)
    np.testing.assert_allclose(f, loads.patterns @ [20.0, 15.0, 4.0, 3.0])
    force, moment = resultants(system, f)
    np.testing.assert_allclose(force, [0, 0, 23.0], atol=1e-8)
    np.testing.assert_allclose(moment @ loads.axis, 19.0, rtol=1e-10)


def test_bad_load_options_are_user_errors():
    station, system = station_system(THICKNESS, TIPS, 1, 1)
    with pytest.raises(UserError, match="'bottom' or 'wall'"):
        hole_loads(system, station, evacuation_thrust_on="flute")
    with pytest.raises(UserError, match="finite"):
        hole_loads(system, station, growth_exponent=np.nan)


def test_allotta_cone_traction_is_a_constant_force_per_unit_lip_length():
    """Allotta's model cuts a constant force per unit depth of the cone, so per unit lip length: the
    share of the thrust inside radius a is a / R (a uniform traction gives (a / R)²)."""
    station, system = station_system(THICKNESS, TIPS, 1, 2)
    local = station.hole.frame.to_local(system.nodes)
    inner = np.hypot(local[:, 0], local[:, 1]) < 0.5 * RADIUS
    shares = {}
    for traction in ("allotta", "uniform"):
        thrust = hole_loads(system, station, cone_traction=traction).cutting_thrust.reshape(-1, 3)
        shares[traction] = thrust[inner].sum(axis=0) @ station.hole.frame.axis
    assert shares["allotta"] == pytest.approx(0.5, abs=0.03)
    assert shares["uniform"] == pytest.approx(0.25, abs=0.03)
