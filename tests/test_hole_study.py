"""The submodel's pieces: global displacements onto the cut faces, distances from the hole,
and the stress/strain measures, against fields the elements represent exactly."""

import numpy as np
import pytest

from hole_cases import E_MPA, NU, assemble_model, plate, station_system
from femstudy.fe.materials import isotropic_stiffness
from femstudy.fe.post import von_mises
from femstudy.hole import node_dofs, offset_samples
from femstudy.hole.coupling import cut_boundary
from femstudy.hole.measures import distance_measures, exclusion_measures
from femstudy.errors import UserError
from femstudy.hole.samples import hole_distance
from femstudy.hole.study import HoleOptions, station_tips

THICKNESS = 4.0
TIPS = (2.5, 5.0)


def quadratic_field(x):
    X, Y, Z = x.T
    return 1e-3 * np.column_stack([X * X + 2 * Y * Z + X, Y * Y - X * Z + 0.5 * Z, Z * Z + X * Y - Y])


def test_cut_boundary_takes_the_global_field_exactly():
    """A quadratic field on a wider P2 plate (R 12 mm, undrilled) is read at the local model's
    cut-face nodes (R 8 mm) to round-off, on both faces of the plate and on the rim."""
    wide = assemble_model(plate(THICKNESS, TIPS, 1.0, 12.0).mesh, 2)
    station, local = station_system(THICKNESS, TIPS, 1, 2)
    fields = np.column_stack([quadratic_field(wide.nodes).ravel(), 2 * quadratic_field(wide.nodes).ravel()])
    cut = cut_boundary(wide, fields, local, station)
    nodes = np.unique(cut.dofs // 3)
    assert np.array_equal(cut.dofs, node_dofs(nodes).ravel())
    radius = np.hypot(local.nodes[nodes, 0], local.nodes[nodes, 1])
    assert np.all((radius > 7.9) & (radius < 8.0 + 1e-9))  # the lateral cut (mid-nodes on chords); faces free
    exact = quadratic_field(local.nodes[nodes]).ravel()
    assert np.max(np.abs(cut.values[:, 0] - exact)) < 1e-12
    assert np.max(np.abs(cut.values[:, 1] - 2 * exact)) < 1e-12


def test_hole_distance_is_the_offset_of_the_samples():
    station = plate(THICKNESS, TIPS).at_station(1)
    for delta in (0.5, 1.0, 2.0):
        samples = offset_samples(station, delta)
        assert np.allclose(hole_distance(station, samples.points), delta, rtol=1e-9)
    inside = station.hole.frame.to_global(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, station.corner_depth_mm - 0.1]]))
    assert np.all(hole_distance(station, inside) == 0.0)


def test_measures_of_a_uniform_strain():
    """An affine displacement has one strain everywhere: the measures must return its von Mises
    stress, principal stresses and strains (exact to round-off), at every distance and outside
    every exclusion radius; points closer than a radius are not counted."""
    station, system = station_system(THICKNESS, TIPS, 1, 2)
    gradient = 1e-4 * np.array([[3.0, 1.0, 0.0], [0.5, -2.0, 1.0], [0.0, 1.5, 1.0]])
    u = (system.nodes @ gradient.T).ravel()[:, None]
    strain_tensor = 0.5 * (gradient + gradient.T)
    D = isotropic_stiffness(E_MPA, NU)
    voigt = np.array([strain_tensor[0, 0], strain_tensor[1, 1], strain_tensor[2, 2], 2 * strain_tensor[1, 2],
                      2 * strain_tensor[0, 2], 2 * strain_tensor[0, 1]])
    stress = D @ voigt
    sigma = np.array([[stress[0], stress[5], stress[4]], [stress[5], stress[1], stress[3]],
                      [stress[4], stress[3], stress[2]]])
    principal_stress, principal_strain = np.linalg.eigvalsh(sigma), np.linalg.eigvalsh(strain_tensor)
    axis = np.array([0.0, 1.0, 0.0])
    excluded = np.zeros((system.n_tets, len(system.ref.weights)), bool)
    measures = (distance_measures(system, station, u, (0.5, 2.0), axis)
                + exclusion_measures(system, station, u, (1.0, 3.0), axis, excluded))
    for m in measures:
        assert m.points > 0
        assert abs(m.von_mises_MPa - von_mises(stress)) < 1e-9 * von_mises(stress)
        assert abs(m.max_principal_stress_MPa - principal_stress[-1]) < 1e-9 * np.abs(principal_stress).max()
        assert abs(m.min_principal_stress_MPa - principal_stress[0]) < 1e-9 * np.abs(principal_stress).max()
        assert abs(m.max_principal_strain - principal_strain[-1]) < 1e-9 * np.abs(principal_strain).max()
        assert abs(m.min_principal_strain - principal_strain[0]) < 1e-9 * np.abs(principal_strain).max()
        assert m.location_distance_mm >= m.radius_mm - 1e-9
    kinds = [m.kind for m in measures]
    assert kinds == ["distance", "wall", "distance", "wall", "exclusion", "exclusion"]
    assert measures[0].points > measures[1].points  # the wall's points are a part of the set
    assert measures[4].points > measures[5].points  # fewer points outside the larger radius


def test_the_deepest_tip_stops_a_ligament_short_of_the_bottom():
    options = HoleOptions(stations=2, ligament_mm=0.5)
    np.testing.assert_allclose(station_tips(options, 6.0, 6.08), [2.79, 5.58])  # the canal decides
    np.testing.assert_allclose(station_tips(options, 5.0, 6.08), [2.5, 5.0])  # the drill stops first
    np.testing.assert_allclose(station_tips(options, 5.0, np.inf), [2.5, 5.0])  # solid to the depth cap
    with pytest.raises(UserError, match="no bone to drill"):
        station_tips(options, 6.0, 0.4)
