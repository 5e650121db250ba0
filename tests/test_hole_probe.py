"""Point probes reproduce fields the elements contain; offset samples lie at the stated
distance from the hole."""

import numpy as np
import pytest

from hole_cases import CONE, RADIUS, station_system
from femstudy.fe.materials import isotropic_stiffness
from femstudy.hole import offset_samples, point_probe

THICKNESS = 4.0
TIPS = (2.5, 6.0)


def quadratic_field(x):
    """A displacement field [mm] with quadratic terms, and its strain (Voigt, engineering shear)."""
    X, Y, Z = x.T
    u = 1e-3 * np.column_stack([X * X + 2 * Y * Z + X, Y * Y - X * Z + 0.5 * Z, Z * Z + X * Y - Y])
    strain = 1e-3 * np.column_stack([2 * X + 1, 2 * Y, 2 * Z, np.full_like(X, -0.5), 3 * Y, Z])
    return u, strain


def points_in_cells(system, n, seed):
    rng = np.random.default_rng(seed)
    cells = rng.choice(system.n_tets, n, replace=False)
    weights = rng.dirichlet(np.ones(4), n)
    return np.einsum("nk,nkj->nj", weights, system.mesh.p.T[system.mesh.t.T[cells]])


@pytest.fixture(scope="module")
def p2():
    return station_system(THICKNESS, TIPS, 0, 2)


def test_p2_probe_reproduces_a_quadratic_field(p2):
    station, system = p2
    u_nodes, _ = quadratic_field(system.nodes)
    points = points_in_cells(system, 200, 1)
    result = point_probe(system, points)
    assert result.inside.all()
    u, strain = quadratic_field(points)
    np.testing.assert_allclose(result.displacement(u_nodes.ravel()), u, atol=1e-12)
    D = isotropic_stiffness(16e3, 0.4)
    np.testing.assert_allclose(result.stress(u_nodes.ravel()), strain @ D.T, atol=1e-9)


def test_p1_probe_and_several_load_cases():
    station, system = station_system(THICKNESS, TIPS, 0, 1)
    linear = np.column_stack([system.nodes @ [1e-3, 0, 0], system.nodes @ [0, 2e-3, 1e-3], np.zeros(len(system.nodes))])
    points = points_in_cells(system, 50, 2)
    result = point_probe(system, points)
    two = np.column_stack([linear.ravel(), 2 * linear.ravel()])
    s = result.stress(two)
    assert s.shape == (50, 2, 6)
    np.testing.assert_allclose(s[:, 1], 2 * s[:, 0], rtol=1e-12)
    np.testing.assert_allclose(result.displacement(two)[:, 0], points @ np.array([[1e-3, 0, 0], [0, 2e-3, 0],
                                                                                   [0, 1e-3, 0]]), atol=1e-12)


def test_points_outside_are_reported_not_zero(p2):
    station, system = p2
    points = np.array([[0.0, 0.0, 0.5],  # in the drilled hole
                       [0.0, 0.0, -1.0],  # above the top
                       [3.0, 0.0, 1.0],  # in bone
                       [0.0, 20.0, 1.0]])  # beyond the submodel
    result = point_probe(system, points)
    assert result.outside.tolist() == [0, 1, 3]
    s = result.stress(np.ones(system.n_dofs))
    assert np.isnan(s[[0, 1, 3]]).all() and np.isfinite(s[2]).all()


def test_boundary_vertices_are_found(p2):
    station, system = p2
    wall = np.unique(station.faces["hole_wall"])
    assert point_probe(system, station.mesh.points[wall]).inside.all()


def distance_to_hole(points, corner, tip):
    """Exact distance [mm] from local points to the convex hole {r ≤ R, ζ ≤ s + (R − r) l/R},
    computed in the (r, ζ) half-plane as the distance to its two boundary segments."""
    r, zeta = np.hypot(points[:, 0], points[:, 1]), points[:, 2]
    q = np.column_stack([r, zeta])

    def to_segment(a, b):
        t = np.clip(((q - a) @ (b - a)) / ((b - a) @ (b - a)), 0, 1)
        return np.linalg.norm(q - (a + t[:, None] * (b - a)), axis=1)

    wall = to_segment(np.array([RADIUS, -100.0]), np.array([RADIUS, corner]))
    cone = to_segment(np.array([RADIUS, corner]), np.array([0.0, tip]))
    return np.minimum(wall, cone)


@pytest.mark.parametrize("delta", [0.5, 1.0, 2.0, 5.0])
def test_offset_samples_are_at_the_distance(p2, delta):
    station, system = p2
    samples = offset_samples(station, delta)
    local = station.hole.frame.to_local(samples.points)
    np.testing.assert_allclose(distance_to_hole(local, station.corner_depth_mm, station.tip_depth_mm), delta,
                               rtol=1e-9)
    assert {0, 1, 2, 3} == set(np.unique(samples.part))
    assert local[:, 2].min() == pytest.approx(0.0, abs=1e-12)  # from the top surface down
    assert samples.of("tip").sum() >= 1
    # neighbours on a circle are at most one spacing apart
    wall = local[samples.of("wall")]
    ring = wall[np.isclose(wall[:, 2], wall[0, 2])]
    theta = np.sort(np.arctan2(ring[:, 1], ring[:, 0]))
    assert (RADIUS + delta) * np.diff(theta).max() <= samples.spacing_mm * (1 + 1e-9)
    inside = point_probe(system, samples.points).inside
    assert inside.mean() > (0.5 if delta == 5.0 else 0.9)  # some fall below the 4 mm plate


def test_cone_of_the_station_is_sampled(p2):
    station, _ = p2
    samples = offset_samples(station, 0.5)
    local = station.hole.frame.to_local(samples.points[samples.of("cone")])
    r = np.hypot(local[:, 0], local[:, 1])
    # the cone moved 0.5 mm along its normal (45°): ζ = s + (R − r) + 0.5 √2
    np.testing.assert_allclose(local[:, 2], station.corner_depth_mm + (RADIUS - r) * CONE / RADIUS + 0.5 * np.sqrt(2),
                               atol=1e-9)


def test_boundary_points_lie_on_the_bone_surface_the_curve_leaves_through(p2):
    """At δ = 2 mm below a 2.5 mm tip in a 4 mm plate the tip arc leaves through the bottom
    face ζ = 4: the added points sit on that face (to the bisection's 2⁻¹² of a spacing), in
    the bone, and on the curve; without them the deepest sample stops up to a spacing short."""
    from femstudy.hole.probe import MeshLocator

    station, system = p2
    locator = MeshLocator(system)
    samples = offset_samples(station, 2.0)
    clipped = samples.with_boundary_points(locator.label)
    added = clipped.points[len(samples.points):]
    zeta = station.hole.frame.to_local(added)[:, 2]
    assert len(added) >= 8 and (locator.label(added) >= 0).all()
    bottom = zeta > 2.0
    assert bottom.any()
    np.testing.assert_allclose(zeta[bottom], THICKNESS, atol=samples.spacing_mm / 2 ** 12)
    np.testing.assert_allclose(distance_to_hole(station.hole.frame.to_local(added), station.corner_depth_mm,
                                                station.tip_depth_mm), 2.0, rtol=1e-9)
    deepest_sample = station.hole.frame.to_local(samples.points[locator.label(samples.points) >= 0])[:, 2].max()
    assert THICKNESS - deepest_sample > samples.spacing_mm / 2 ** 10


def test_boundary_points_straddle_a_material_interface():
    """Where the 0.5 mm curve passes from cortex into cancellous bone (the layered plate, station
    at the 4 mm tip) a point is added on either side, each in an element of its own region and
    within the bisection's 2⁻¹² of a spacing (plus the chords' sag, < 5 µm) of the interface,
    where the von Mises stress jumps: without them the samples miss it by up to a spacing."""
    from hole_cases import assemble_model, inner_cortex, layered_plate
    from femstudy.femur_mesh import CANCELLOUS_DISTAL, CORTICAL
    from femstudy.hole.probe import MeshLocator

    station = layered_plate().at_station(1)
    system = assemble_model(station.mesh, 1)
    locator = MeshLocator(system)
    samples = offset_samples(station, 0.5)
    added = samples.with_boundary_points(locator.label).points[len(samples.points):]
    label = locator.label(added)
    local = station.hole.frame.to_local(added)
    gap = local[:, 2] - inner_cortex(local[:, :2])
    at_interface = np.abs(gap) < 0.005 + samples.spacing_mm / 2 ** 12
    assert np.sum(at_interface & (label == CORTICAL)) >= 24 and np.sum(at_interface & (label == CANCELLOUS_DISTAL)) >= 24
    assert np.all(gap[at_interface & (label == CORTICAL)] < 0.005)  # each on its own side
    assert np.all(gap[at_interface & (label == CANCELLOUS_DISTAL)] > -0.005)
    sample_local = station.hole.frame.to_local(samples.points[locator.label(samples.points) >= 0])
    assert np.abs(sample_local[:, 2] - inner_cortex(sample_local[:, :2])).min() > samples.spacing_mm / 2 ** 10


def test_points_just_inside_any_element_are_found_in_it(p2):
    """A point 1e-5 (barycentric) inside one face of each element lies in that element and no
    other: the locator finds it there, however far the element's centroid is from the point."""
    station, system = p2
    rng = np.random.default_rng(3)
    n = system.n_tets
    weights = np.column_stack([np.full(n, 1e-5), rng.dirichlet(np.ones(3), n) * (1 - 1e-5)])
    first = rng.integers(0, 4, n)  # the vertex opposite the face the point is near
    corners = system.mesh.p.T[system.mesh.t.T]  # (n, 4, 3)
    turned = corners[np.arange(n)[:, None], (np.arange(4)[None] + first[:, None]) % 4]
    points = np.einsum("nk,nkj->nj", weights, turned)
    found = point_probe(system, points).element
    assert (found == np.arange(n)).all(), f"{np.sum(found != np.arange(n))} of {n} points placed elsewhere"


def test_kept_sample_points_are_the_computed_ones_and_a_tampered_store_is_not_used(p2, tmp_path, caplog):
    """distance_samples with a keep folder stores its points once and serves them again; a store
    whose points were moved off their distance is ignored (logged) and the points recomputed."""
    from femstudy.hole.measures import distance_samples, samples_fingerprint

    station, system = p2
    fresh = distance_samples(system, station, (0.5, 1.0))
    first = distance_samples(system, station, (0.5, 1.0), tmp_path)
    stored = tmp_path / f"samples-{samples_fingerprint(system, station, (0.5, 1.0))}.npz"
    assert stored.is_file()
    again = distance_samples(system, station, (0.5, 1.0), tmp_path)
    for a, b, c in zip(fresh, first, again):
        for part in ("points", "element", "wall"):
            np.testing.assert_array_equal(getattr(a, part), getattr(b, part))
            np.testing.assert_array_equal(getattr(a, part), getattr(c, part))
    arrays = dict(np.load(stored))
    arrays["points_1"] = arrays["points_1"] * 1.001
    np.savez(stored, **arrays)
    with caplog.at_level("WARNING"):
        mended = distance_samples(system, station, (0.5, 1.0), tmp_path)
    assert "fail the check" in caplog.text
    np.testing.assert_array_equal(mended[1].points, fresh[1].points)
