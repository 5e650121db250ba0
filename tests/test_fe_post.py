"""Stress recovery, von Mises and the per-step response summary."""

import numpy as np
import pytest

from fe_cases import LENGTH, R_OUT, clamped_both_ends, tube
from femstudy.fe import drill_patch, response, solve_static, von_mises, von_mises_nodal
from femstudy.femur_model import DrillSite


def test_von_mises_of_simple_states():
    assert von_mises(np.array([100.0, 0, 0, 0, 0, 0])) == pytest.approx(100.0)  # uniaxial
    assert von_mises(np.array([0, 0, 0, 0, 0, 50.0])) == pytest.approx(50.0 * np.sqrt(3))  # pure shear
    assert von_mises(np.array([-70.0, -70.0, -70.0, 0, 0, 0])) == pytest.approx(0.0)  # hydrostatic


def test_uniform_stress_projects_to_itself_at_the_nodes():
    system = tube(1, 12, 12, 2)
    strain = 1e-3  # uniform axial strain u_z = ε z (a field the P2 space holds exactly)
    u = np.zeros((len(system.nodes), 3))
    u[:, 2] = strain * system.nodes[:, 2]
    D = system.materials.D[0]
    expected = von_mises(D @ np.array([0, 0, strain, 0, 0, 0]))
    np.testing.assert_allclose(von_mises_nodal(system, u.ravel()), expected, rtol=1e-10)


@pytest.fixture(scope="module")
def drilled():
    system = tube(1, 32, 60, 2)
    site = DrillSite("top", np.array([0.0, R_OUT, LENGTH / 2]), np.array([0.0, 1.0, 0.0]),
                     np.array([0.0, -1.0, 0.0]), 7.5)
    patch = drill_patch(system, site, 1.35)
    bc = clamped_both_ends(system)
    f = patch.force(30.0, 100.0)
    return system, patch, f, solve_static(system, bc, f)


def test_response_summary(drilled):
    system, patch, f, u = drilled
    out = response(system, u, patch, exclusion_radius_mm=4.0)
    assert out["strain_energy_mJ"] == pytest.approx(0.5 * f @ u, rel=1e-8)  # Clapeyron
    # the drill pushes the top of the tube down: the footprint moves along the drill axis
    assert out["drill_point_axial_mm"] > 0.9 * out["drill_point_deflection_mm"] > 0
    assert out["max_deflection_mm"] >= out["drill_point_deflection_mm"]
    assert abs(out["max_deflection_at_mm"][2] - LENGTH / 2) < 20.0  # at mid-span
    # peak stress sits under the load; outside the exclusion radius it is lower and farther away
    assert out["max_von_mises_outside_MPa"] < out["max_von_mises_MPa"]
    assert np.linalg.norm(np.subtract(out["max_von_mises_at_mm"], patch.centre)) < 4.0
    assert np.linalg.norm(np.subtract(out["max_von_mises_outside_at_mm"], patch.centre)) > 4.0
    assert out["regions"]["cortical"]["max_von_mises_MPa"] == out["max_von_mises_MPa"]
