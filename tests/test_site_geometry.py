"""The bone at a drill site read off its surfaces (femstudy/meshing/site_surface.py), the loads
that follow the bone the drill crosses (femstudy/drilling), the cortical strain criterion
(femstudy/failure.py) and the cone traction of Allotta's model (femstudy/hole/loads.py)."""

import logging
from types import SimpleNamespace

import numpy as np
import pytest

from femstudy.drilling import DrillingConditions, evaluate
from femstudy.failure import CorticalStrainLimits, strain_ratio
from femstudy.meshing.frame import Frame, detect_units
from femstudy.meshing.site_surface import local_axis, site_surface

R, LENGTH, CORTEX = 14.0, 400.0, 6.0


def tube_surface(n_theta: int = 360, n_z: int = 81):
    """A closed cylinder of radius R about z, LENGTH long, finely triangulated [mm]."""
    theta = np.linspace(0, 2 * np.pi, n_theta, endpoint=False)
    z = np.linspace(0.0, LENGTH, n_z)
    T, Z = np.meshgrid(theta, z, indexing="ij")
    points = np.column_stack([R * np.cos(T.ravel()), R * np.sin(T.ravel()), Z.ravel()])
    index = np.arange(n_theta * n_z).reshape(n_theta, n_z)
    a, b = index, np.roll(index, -1, axis=0)
    quads = np.stack([a[:, :-1], b[:, :-1], b[:, 1:], a[:, 1:]], axis=-1).reshape(-1, 4)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return points, triangles


FRAME = Frame("mm", 1.0, np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), "left", LENGTH, LENGTH)
GEOMETRY = SimpleNamespace(cortex=SimpleNamespace(midshaft_mm=CORTEX, epiphysis_mm=CORTEX),
                           canal=SimpleNamespace(proximal_fraction=0.2, distal_fraction=0.8))


@pytest.fixture(scope="module")
def patch():
    points, triangles = tube_surface()
    return site_surface(points, triangles, np.array([R, 0.0, 200.0]), 40.0, FRAME, GEOMETRY)


def test_the_cortex_rule_ends_the_cortex_its_thickness_below_the_surface(patch):
    """Radially into a tube, the cortex ends CORTEX below the surface; on a ray parallel to it at
    an offset b it ends where the distance to the surface is CORTEX: at depth
    sqrt(R² − b²) − sqrt((R − CORTEX)² − b²). The surface's faceting (360 sides) is 0.5 µm."""
    starts = np.array([[R, 0.0, 200.0]])
    assert patch.cortex_crossing(starts, np.array([-1.0, 0, 0]), 20.0)[0] == pytest.approx(CORTEX, abs=1e-3)
    b = 5.0
    start = np.array([[np.sqrt(R ** 2 - b ** 2), b, 200.0]])
    expected = np.sqrt(R ** 2 - b ** 2) - np.sqrt((R - CORTEX) ** 2 - b ** 2)
    assert patch.cortex_crossing(start, np.array([-1.0, 0, 0]), 20.0)[0] == pytest.approx(expected, abs=1e-3)
    beside = np.array([[np.sqrt(R ** 2 - 9.0 ** 2), 9.0, 200.0]])  # passes outside the inner circle: all cortex
    assert np.isinf(patch.cortex_crossing(beside, np.array([-1.0, 0, 0]), 20.0)[0])


def test_the_local_axis_of_a_tube_is_its_axis_and_a_ball_has_none(patch):
    axis, evidence = local_axis(patch, np.array([0.1, 0.0, 1.0]))
    assert evidence["axis"] == "local" and abs(axis @ np.array([0, 0, 1.0])) == pytest.approx(1.0, abs=1e-6)
    phi, theta = np.meshgrid(np.linspace(0.05, np.pi - 0.05, 90), np.linspace(0, 2 * np.pi, 180, endpoint=False))
    points = np.column_stack([20 * np.sin(phi.ravel()) * np.cos(theta.ravel()), 20 * np.sin(phi.ravel()) *
                              np.sin(theta.ravel()), 200 + 20 * np.cos(phi.ravel())])
    from scipy.spatial import ConvexHull

    ball = site_surface(points, ConvexHull(points).simplices, np.array([20.0, 0, 200.0]), 40.0, FRAME, GEOMETRY)
    fallback = np.array([0, 0, 1.0])
    axis, evidence = local_axis(ball, fallback)
    assert evidence["axis"] == "femur long axis" and np.allclose(axis, fallback)


def test_beyond_the_cortex_the_drill_cuts_cancellous_bone_or_nothing_in_the_canal():
    """A 2 mm cortex drilled 6 mm: Allotta's thrust in cancellous bone is u2's share of the
    cortex's; into the canal there is nothing to cut once the cone is through."""
    t = np.array([1.0, 3.0])  # tip at 2 mm (in the cortex, full engagement) and 6 mm (cone 4 mm past it)
    into_bone = DrillingConditions(2.0, 1500.0, 2.0, beyond_cortex="cancellous")
    into_canal = DrillingConditions(2.0, 1500.0, 2.0, beyond_cortex="canal")
    bone, canal = evaluate("allotta", into_bone, t), evaluate("allotta", into_canal, t)
    assert bone.thrust_N[0] == pytest.approx(canal.thrust_N[0])
    assert bone.thrust_N[1] / bone.thrust_N[0] == pytest.approx(into_bone.bone.u2_MPa / into_bone.bone.u1_MPa)
    assert canal.thrust_N[1] == 0.0 and canal.torque_Nmm[1] == 0.0


def test_the_strain_criterion_is_the_load_factor_to_the_first_limit():
    limits = CorticalStrainLimits()
    ratio = strain_ratio(np.array([0.00365, 0.0, 0.001]), np.array([-0.0, -0.0052, -0.0104]), limits)
    assert ratio == pytest.approx([2.0, 2.0, 1.0])
    assert np.isinf(strain_ratio(np.array([0.0]), np.array([0.0]))[0])


def test_units_other_than_mm_are_said_in_one_line_with_every_length(caplog):
    with caplog.at_level(logging.INFO, logger="femstudy"):
        assert detect_units(9.3, "auto")[0] == "in"
    line = caplog.records[-1].getMessage()
    assert "read as in" in line and "236.2 mm as in" in line and "9.3 mm as mm" in line
    with caplog.at_level(logging.INFO, logger="femstudy"):
        assert detect_units(455.0, "auto")[0] == "mm"
    assert all("read as mm" not in r.getMessage() for r in caplog.records)
