"""The drill patch's discrete resultants, and the clamps."""

import numpy as np
import pytest

from fe_cases import LENGTH, R_OUT, end_facets, tube
from femstudy.errors import UserError
from femstudy.fe import assemble, clamp, drill_patch
from femstudy.fe.geometry import tube_mesh
from femstudy.femur_mesh import Clamps, DrillSite, TetMesh

RADIUS = 1.35  # the thesis's 2.7 mm drill


def top_site(direction=(0.0, -1.0, 0.0)):
    """Mid-span on top of the tube, drilling straight down (−y) into it."""
    return DrillSite("top", np.array([0.0, R_OUT, LENGTH / 2]), np.array([0.0, 1.0, 0.0]), np.array(direction), 7.5)


def resultants(system, f, centre):
    """Net force Σ f_i [N] and moment Σ (x_i − c) × f_i [N·mm] of nodal forces."""
    forces = f.reshape(-1, 3)
    return forces.sum(axis=0), np.cross(system.nodes - centre, forces).sum(axis=0)


@pytest.fixture(scope="module", params=[2, 1], ids=["P2", "P1"])
def loaded(request):
    system = tube(1, 32, 60, request.param)
    return system, drill_patch(system, top_site(), RADIUS)


def test_thrust_is_one_newton_along_the_drill(loaded):
    system, patch = loaded
    force, moment = resultants(system, patch.thrust, patch.centre)
    # 1e-6 relative (the tolerance); exact up to round-off by construction
    np.testing.assert_allclose(force, [0.0, -1.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(moment, 0.0, atol=1e-6 * RADIUS)  # centred on the footprint


def test_torque_has_no_net_force_and_a_unit_moment_about_the_drill(loaded):
    system, patch = loaded
    force, moment = resultants(system, patch.torque, patch.centre)
    typical_force = 1.0 / RADIUS  # a 1 N·mm moment made of forces at about the drill radius
    np.testing.assert_allclose(force, 0.0, atol=1e-6 * typical_force)
    assert moment @ patch.axis == pytest.approx(1.0, rel=1e-6)
    # off-axis moment from the surface's curvature: zero here by the tube's symmetry
    assert np.linalg.norm(moment - (moment @ patch.axis) * patch.axis) < 1e-6


def test_footprint_is_the_drill_disk_on_the_near_surface(loaded):
    system, patch = loaded
    # sub-triangles of ≤ r/10 resolve the disk's rim: area within 3 % of π r²
    assert patch.area_mm2 == pytest.approx(np.pi * RADIUS ** 2, rel=0.03)
    assert np.linalg.norm(patch.centre - top_site().entry_point) < 0.05 * RADIUS
    loaded_nodes = np.unique(np.flatnonzero(np.abs(patch.thrust) > 0) // 3)
    assert system.nodes[loaded_nodes, 1].min() > R_OUT - 1.0  # nothing on the canal or the far side
    translation = np.tile([0.1, -0.2, 0.3], len(system.nodes))
    np.testing.assert_allclose(patch.mean @ translation, [0.1, -0.2, 0.3], rtol=1e-12)
    assert patch.thrust @ translation == pytest.approx(0.2, rel=1e-12)


def test_sites_off_the_surface_or_facing_away_are_refused():
    system = tube(1, 32, 60, 2)
    away = DrillSite("outside", np.array([0.0, R_OUT + 10.0, LENGTH / 2]), np.array([0.0, 1.0, 0.0]),
                     np.array([0.0, -1.0, 0.0]), 7.5)
    with pytest.raises(UserError, match="touches no mesh surface facing the drill"):
        drill_patch(system, away, RADIUS)
    with pytest.raises(UserError, match="touches no mesh surface facing the drill"):
        drill_patch(system, top_site(direction=(0.0, 1.0, 0.0)), RADIUS)


def end_masks(system, length=LENGTH):
    z = system.mesh.p[2]
    return Clamps(proximal=np.isclose(z, 0.0), distal=np.isclose(z, length))


def test_clamps_fix_every_node_of_the_fully_clamped_facets():
    system = tube(1, 32, 60, 2)
    bc = clamp(system, end_masks(system))
    ends = np.concatenate([end_facets(system, 0.0), end_facets(system, LENGTH)])
    np.testing.assert_array_equal(np.sort(bc.facets), np.sort(ends))
    fixed_nodes = np.unique(bc.fixed // 3)
    expected = np.flatnonzero(np.isclose(system.nodes[:, 2], 0.0) | np.isclose(system.nodes[:, 2], LENGTH))
    np.testing.assert_array_equal(fixed_nodes, expected)  # vertices and P2 mid-edge nodes
    assert len(bc.fixed) == 3 * len(expected) and len(bc.free) + len(bc.fixed) == system.n_dofs


def test_clamps_that_fix_nothing_or_leave_a_floating_piece_are_refused():
    system = tube(1, 32, 60, 2)
    nothing = np.zeros(system.mesh.nvertices, dtype=bool)
    with pytest.raises(UserError, match="select no boundary facet"):
        clamp(system, Clamps(nothing, nothing))
    lonely = nothing.copy()
    lonely[0] = True  # a single point completes no facet
    with pytest.raises(UserError, match="select no boundary facet"):
        clamp(system, Clamps(lonely, nothing))
    with pytest.raises(UserError, match="mesh has"):
        clamp(system, Clamps(nothing[:-1], nothing[:-1]))

    a, b = tube_mesh(50.0, 10.0, 5.0, 1, 8, 4), tube_mesh(50.0, 10.0, 5.0, 1, 8, 4)
    two = TetMesh(np.vstack([a.points, b.points + [100.0, 0, 0]]), np.vstack([a.tets, b.tets + len(a.points)]),
                  np.concatenate([a.region, b.region]))
    system = assemble(two, order=1)
    first = np.arange(len(two.points)) < len(a.points)
    z = two.points[:, 2]
    with pytest.raises(UserError, match="1 of the mesh's 2 disconnected pieces"):
        clamp(system, Clamps(first & np.isclose(z, 0.0), first & np.isclose(z, 50.0)))
