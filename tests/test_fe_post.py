"""Stress recovery, von Mises, and response measures with exact maxima over long histories."""

import numpy as np
import pytest

from fe_cases import LENGTH, R_OUT, clamped_both_ends, tube
from femstudy.fe import (StepRecorder, deflection_channel, drill_patch, element_stress, factorize, point_channel,
                         reduced_history, solve_static, von_mises, von_mises_channel, von_mises_nodal)
from femstudy.fe.post import VON_MISES_ROWS, quadrature_points
from femstudy.femur_mesh import DrillSite


def test_von_mises_of_simple_states():
    assert von_mises(np.array([100.0, 0, 0, 0, 0, 0])) == pytest.approx(100.0)  # uniaxial
    assert von_mises(np.array([0, 0, 0, 0, 0, 50.0])) == pytest.approx(50.0 * np.sqrt(3))  # pure shear
    assert von_mises(np.array([-70.0, -70.0, -70.0, 0, 0, 0])) == pytest.approx(0.0)  # hydrostatic
    s = np.random.default_rng(1).normal(size=(50, 6))  # ‖T σ‖ is the textbook formula
    textbook = np.sqrt(0.5 * ((s[:, 0] - s[:, 1]) ** 2 + (s[:, 1] - s[:, 2]) ** 2 + (s[:, 2] - s[:, 0]) ** 2)
                       + 3 * (s[:, 3:] ** 2).sum(axis=1))
    np.testing.assert_allclose(np.linalg.norm(s @ VON_MISES_ROWS.T, axis=1), textbook, rtol=1e-12)


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
    fs = factorize(system, clamped_both_ends(system))
    points = quadrature_points(system).reshape(-1, 3)
    outside = np.linalg.norm(points - patch.centre, axis=1) > 4.0
    channels = [deflection_channel(system), point_channel("drill_point", patch.mean, patch.centre),
                von_mises_channel(system, {"outside": outside})]
    return system, patch, fs, channels


def test_measures_of_one_field_are_the_direct_maxima(drilled):
    system, patch, fs, channels = drilled
    u = solve_static(fs, patch.force(30.0, 100.0))
    recorder = StepRecorder(channels, 1)
    recorder.step(0, u)
    history = recorder.history()
    nodal = np.linalg.norm(u.reshape(-1, 3), axis=1)
    vm = von_mises(element_stress(system, u)).ravel()
    points = quadrature_points(system).reshape(-1, 3)
    outside = np.linalg.norm(points - patch.centre, axis=1) > 4.0
    assert history["deflection"].peak == pytest.approx(nodal.max(), rel=1e-12)
    np.testing.assert_allclose(history["deflection"].peak_location, system.nodes[np.argmax(nodal)])
    assert history["drill_point"].peak == pytest.approx(np.linalg.norm(patch.mean @ u), rel=1e-12)
    assert history["von_mises"].peak == pytest.approx(vm.max(), rel=1e-12)
    assert history["von_mises/outside"].peak == pytest.approx(vm[outside].max(), rel=1e-12)
    # the peak stress sits under the load; outside the exclusion radius it is lower and farther away
    assert np.linalg.norm(history["von_mises"].peak_location - patch.centre) < 4.0
    assert np.linalg.norm(history["von_mises/outside"].peak_location - patch.centre) > 4.0
    assert history["von_mises/outside"].peak < history["von_mises"].peak
    # the drill pushes the top of the tube down: the footprint moves along the drill axis
    assert patch.axis @ (patch.mean @ u) > 0.9 * history["drill_point"].peak


def test_long_histories_are_sampled_but_their_peaks_are_exact(drilled, monkeypatch):
    """Two thousand steps of a fast oscillation on the model's static shapes: the series is
    recorded at coarse steps, the maxima over all steps equal an evaluation at every step."""
    from femstudy.fe import outputs

    system, patch, fs, channels = drilled
    basis = np.linalg.qr(np.column_stack([solve_static(fs, p) for p in patch.patterns.T]))[0]
    n = 2000
    t = np.arange(n) / n
    coordinates = np.vstack([3e-3 * (1 + 0.3 * np.sin(2 * np.pi * 37 * t)),
                             1e-2 * np.exp(t) * (1 + 0.2 * np.sin(2 * np.pi * 53 * t + 1))])
    history = reduced_history(channels, basis, coordinates)
    stiffness = basis.T @ (fs.system.K @ basis)  # the energy metric prunes harder, and stays exact
    energy = reduced_history(channels, basis, coordinates, metric=stiffness)
    assert len(history.recorded_steps) < n / 3
    points = len(system.nodes)  # the bound prunes: far fewer values than every point at every step
    assert history.refined_steps["deflection"] < 0.01 * points * n
    assert energy.refined_steps["deflection"] <= history.refined_steps["deflection"]
    monkeypatch.setattr(outputs, "ALL_STEPS", n)
    every = reduced_history(channels, basis, coordinates)
    assert len(every.recorded_steps) == n
    for name in ("deflection", "drill_point", "von_mises", "von_mises/outside"):
        assert history[name].peak == pytest.approx(every[name].peak, rel=1e-12)
        assert history[name].peak_step == every[name].peak_step == energy[name].peak_step
        assert energy[name].peak == pytest.approx(every[name].peak, rel=1e-12)
        np.testing.assert_allclose(history[name].values, every[name].values[history.recorded_steps], rtol=1e-12)
    # and one step of it equals the direct evaluation of that field
    recorder = StepRecorder(channels, 1)
    recorder.step(0, basis @ coordinates[:, every["von_mises"].peak_step])
    assert recorder.history()["von_mises"].peak == pytest.approx(every["von_mises"].peak, rel=1e-12)


def test_the_vertex_von_mises_of_many_fields_at_once_are_each_fields_own():
    """The views' vertex von Mises of k fields (several passes of a few fields over the projected
    stress rows) equal von_mises_nodal of each field alone, to round-off."""
    from femstudy.study.output import FIELDS_PER_PASS, _von_mises_vertices

    system = tube(1, 12, 12, 2)
    rng = np.random.default_rng(4)
    basis = 1e-3 * rng.standard_normal((3 * len(system.nodes), 4))
    coordinates = rng.standard_normal((4, FIELDS_PER_PASS + 3))   # two passes, the second short
    rows = von_mises_channel(system).project(basis)   # the study's von Mises rows of the basis
    together = _von_mises_vertices(system, rows, coordinates)
    alone = np.column_stack([von_mises_nodal(system, basis @ c) for c in coordinates.T])
    np.testing.assert_allclose(together, alone, rtol=1e-10, atol=1e-12 * alone.max())
