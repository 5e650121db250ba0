"""The column mesher: conformity, orientation, quality, station labels and removed volumes."""

import numpy as np
import pytest

from hole_cases import CONE, DIAMETER, POINT_ANGLE, RADIUS, inner_cortex, layered_plate, plate
from femstudy.errors import UserError
from femstudy.hole import HoleFrame, Resolution, hole_mesh
from femstudy.hole.prisms import split_prisms
from femstudy.hole.rings import disk, graded_points
from femstudy.meshing.tetra import signed_volumes

THICKNESS = 5.0
TIPS = (0.8, 2.0, 3.5, 5.0, 5.9, 9.0)  # entering, two full, breaking through (tip below 5 mm), through
N_WALL = 24


def polygon_area(n: int, radius: float) -> float:
    return 0.5 * n * radius ** 2 * np.sin(2 * np.pi / n)


def faces_of(tets):
    return np.sort(np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]]),
                   axis=1)


def hole_volume(tip: float, thickness: float, n: int = 4000) -> float:
    """Exact volume of the bone drilled away: ∫₀^R 2πr clip(s + (R − r) cot(β/2), 0, H) dr."""
    r = np.linspace(0, RADIUS, n + 1)
    depth = np.clip(tip - CONE + (RADIUS - r) * CONE / RADIUS, 0, thickness)
    f = 2 * np.pi * r * depth
    return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(r)))


def cone_depth(hole, corner, r):
    """Depth of a station's cone at radius r by the documented rule: the exact cone, clipped
    to the plate, and moved onto the bottom where it comes within ``snap`` of a layer
    spacing of it."""
    exact = np.clip(corner + (RADIUS - r) * CONE / RADIUS, 0, THICKNESS)
    offsets = hole.layer_offsets_mm
    j = np.flatnonzero(np.isclose(offsets, corner))
    if len(j) == 0 or j[0] == len(offsets) - 1:  # no layer: the cone lies beyond the plate
        return exact
    spacing = offsets[j[0] + 1] - offsets[j[0]]
    return np.where(THICKNESS - exact < hole.resolution.snap * spacing, THICKNESS, exact)


@pytest.fixture(scope="module")
def hole():
    return plate(THICKNESS, TIPS)


def test_graded_points_hit_the_fixed_points_and_follow_the_size():
    s = graded_points(np.array([0.0, 1.0, 4.0]), lambda x: 0.1 + 0.2 * x)
    assert {0.0, 1.0, 4.0} <= set(np.round(s, 12))
    steps = np.diff(s)
    mid = 0.5 * (s[1:] + s[:-1])
    np.testing.assert_allclose(steps, 0.1 + 0.2 * mid, rtol=0.25)  # n rounds ∫ds/h to an integer


def test_disk_conforms_to_the_hole_circle():
    d = disk(RADIUS, 8.0, 32, 0.2, 1.25)
    corner = d.xy[d.triangles]
    u, v = corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]
    area = 0.5 * (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    assert area.min() > 0
    assert area.sum() == pytest.approx(polygon_area(32, 8.0), rel=1e-12)  # no gap, no overlap
    assert area[d.in_hole].sum() == pytest.approx(polygon_area(32, RADIUS), rel=1e-12)
    on_circle = d.ring == d.hole_ring
    np.testing.assert_allclose(np.hypot(*d.xy[on_circle].T), RADIUS, rtol=1e-14)
    assert on_circle.sum() == 32


def test_minimum_index_split_conforms_on_shared_faces():
    # two prisms sharing the quad (1, 2 | 4, 5)... numbered so the diagonal choice matters
    prisms = np.array([[0, 7, 2, 3, 9, 5], [7, 2, 10, 9, 5, 11]])
    tets, owner = split_prisms(prisms)
    assert len(tets) == 6 and np.bincount(owner).tolist() == [3, 3]
    shared = [set(map(tuple, faces_of(tets[owner == k]))) for k in (0, 1)]
    quad = {7, 2, 9, 5}
    halves = [{f for f in s if set(f) <= quad} for s in shared]
    assert halves[0] == halves[1] and len(halves[0]) == 2  # both cut the quad along one diagonal
    assert split_prisms(np.array([[0, 1, 2, 0, 4, 5]]))[0].shape == (2, 4)  # a collapsed edge: a pyramid


def test_mesh_is_conforming_positive_and_closed(hole):
    tets = hole.mesh.tets
    assert signed_volumes(hole.mesh.points, tets).min() > 0
    _, counts = np.unique(faces_of(tets), axis=0, return_counts=True)
    assert counts.max() == 2  # every face is shared by at most two tetrahedra
    boundary = np.concatenate(list(hole.faces.values()))
    assert len(boundary) == np.sum(counts == 1)  # and every boundary face has a label
    edges = np.sort(np.concatenate([boundary[:, [0, 1]], boundary[:, [1, 2]], boundary[:, [0, 2]]]), axis=1)
    assert set(np.unique(edges, axis=0, return_counts=True)[1]) == {2}  # a closed surface
    volume = signed_volumes(hole.mesh.points, tets).sum()
    assert volume == pytest.approx(polygon_area(N_WALL, 8.0) * THICKNESS, rel=1e-12)


def test_quality_is_reported_and_reasonable(hole):
    # flat cells far from the hole (thin layers under wide outer rings) set the minimum
    assert 10.0 < hole.quality["min_dihedral_deg"] and hole.quality["max_dihedral_deg"] < 140.0  # 10.9°, 135°
    assert hole.summary()["min_dihedral_deg"] == hole.quality["min_dihedral_deg"]


def test_labels_lie_on_their_surfaces(hole):
    local = hole.frame.to_local(hole.mesh.points)
    r, zeta = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
    f = hole.faces
    np.testing.assert_allclose(zeta[f["top"]], 0.0, atol=1e-12)
    np.testing.assert_allclose(zeta[f["bottom_free"]], THICKNESS, atol=1e-12)
    np.testing.assert_allclose(r[f["cut_lateral"]], 8.0, rtol=1e-12)
    assert len(f["cut_bottom"]) == len(f["void"]) == 0
    for k, tip in enumerate(TIPS):
        st = hole.at_station(k)
        s = tip - CONE
        wall, cone = st.faces["hole_wall"], st.faces["hole_bottom"]
        if len(wall):
            np.testing.assert_allclose(r[wall], RADIUS, rtol=1e-12)
            assert zeta[wall].max() == pytest.approx(min(s, THICKNESS), abs=1e-9)
        np.testing.assert_allclose(zeta[cone], cone_depth(hole, s, r[cone]), atol=1e-9)
        assert np.all(r[cone] <= RADIUS * (1 + 1e-12))


def test_wall_area_and_exposed_cone(hole):
    side = 2 * RADIUS * np.sin(np.pi / N_WALL)
    for k, tip in enumerate(TIPS):
        st = hole.at_station(k)
        p = hole.mesh.points
        area = lambda faces: 0.5 * np.linalg.norm(np.cross(p[faces[:, 1]] - p[faces[:, 0]],  # noqa: E731
                                                           p[faces[:, 2]] - p[faces[:, 0]]), axis=1).sum()
        engaged = np.clip(tip - CONE, 0, THICKNESS)
        assert area(st.faces["hole_wall"]) == pytest.approx(N_WALL * side * engaged, rel=1e-12, abs=1e-12)
        if tip < THICKNESS:  # a whole cone, or the part below the entry: faceted within 3 %
            slant = min(tip, CONE) / np.cos(np.radians(POINT_ANGLE) / 2)
            exact = np.pi * min(tip, CONE) * np.tan(np.radians(POINT_ANGLE) / 2) * slant
            assert area(st.faces["hole_bottom"]) == pytest.approx(exact, rel=0.03)
    assert len(hole.at_station(len(TIPS) - 1).faces["hole_bottom"]) == 0  # through
    assert len(hole.at_station(-1).faces["hole_wall"]) == 0


def test_removed_volume_is_the_drilled_hole(hole):
    """Station k removes the cylinder + cone down to its tip: exactly the polygon area per mm
    of advance at full engagement, exactly the disk's piecewise-linear cone (an independent sum
    over the 2-D triangles), and the analytic volume within the faceting error: the hole
    circle is a 24-gon, 1.1 % short in area, and the rings inside it have fewer vertices
    (12 at the entering cone's rim, 4.5 % short), so 5 %."""
    volumes = [hole.removed_volume_mm3(k) for k in range(len(TIPS))]
    assert np.all(np.diff(volumes) > 0)
    a = polygon_area(N_WALL, RADIUS)
    assert volumes[2] - volumes[1] == pytest.approx(a * (TIPS[2] - TIPS[1]), rel=1e-12)
    assert volumes[-1] == pytest.approx(a * THICKNESS, rel=1e-12)
    d = hole.disk
    tri = d.triangles[d.in_hole]
    corner = d.xy[tri]
    u, v = corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]
    area = 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    for k, tip in enumerate(TIPS):
        depth = cone_depth(hole, tip - CONE, d.radius)
        assert volumes[k] == pytest.approx(np.sum(area * depth[tri].mean(axis=1)), rel=1e-12), k
        assert volumes[k] == pytest.approx(hole_volume(tip, THICKNESS), rel=0.05), k
    drilled = hole.station >= 0
    assert np.all(hole.in_hole[drilled])


def test_refinement_scales_every_size():
    coarse, fine = Resolution().scaled, Resolution(refinement=1.5).scaled
    assert fine["n_wall"] == 36 and coarse["n_wall"] == 24
    assert fine["wall_mm"] == pytest.approx(coarse["wall_mm"] / 1.5)
    assert np.log(fine["growth"]) == pytest.approx(np.log(coarse["growth"]) / 1.5)
    n = [plate(1.0, (4.0,), refinement=f).mesh.n_points for f in (1.0, 1.5)]
    assert 2.5 < n[1] / n[0] < 4.5  # ≈ 1.5³ for a three-dimensional refinement


def test_the_ligament_ahead_of_the_deepest_tip_has_thin_layers():
    """The bone between the deepest station's cone and the bottom bends under the thrust: on the
    axis it is crossed by layers no thicker than ``ligament_mm``; drilled through, no layer is
    thinner than ``axial_mm`` needs."""
    bottom = lambda xy: (np.full(len(xy), 6.1), np.ones(len(xy), bool))  # noqa: E731
    flat = lambda xy: np.zeros(len(xy))  # noqa: E731
    frame = HoleFrame.along([0, 0, 0], [0, 0, 1])
    for refinement in (2 / 3, 1.0):
        sizes = Resolution(refinement=refinement).scaled
        hole = hole_mesh(frame, DIAMETER, POINT_ANGLE, 6.0, [1.8, 3.7, 5.5], flat, bottom,
                         resolution=Resolution(refinement=refinement))
        axis = np.linalg.norm(hole.frame.to_local(hole.mesh.points)[:, :2], axis=1) < 1e-12
        depths = np.sort(hole.frame.to_local(hole.mesh.points[axis])[:, 2])
        ligament = depths[(depths >= 5.5 - 1e-9) & (depths <= 6.1 + 1e-9)]
        assert ligament[0] == pytest.approx(5.5) and ligament[-1] == pytest.approx(6.1)
        assert np.diff(ligament).max() <= sizes["ligament_mm"] * 1.2, refinement
        assert len(ligament) - 1 >= int(0.6 / sizes["ligament_mm"])
    through = hole_mesh(frame, DIAMETER, POINT_ANGLE, 6.0, [3.0, 8.0], flat, bottom)
    offsets = through.layer_offsets_mm[through.layer_offsets_mm >= 0]
    assert np.diff(offsets).min() > Resolution().scaled["ligament_mm"] * 1.5
    # 6 mm of bone ahead of the tip is no thin ligament: the thin layers stop 1 mm ahead of it
    deep = lambda xy: (np.full(len(xy), 9.0), np.ones(len(xy), bool))  # noqa: E731
    thick = hole_mesh(frame, DIAMETER, POINT_ANGLE, 6.0, [1.5, 3.0], flat, deep)
    axis = np.linalg.norm(thick.frame.to_local(thick.mesh.points)[:, :2], axis=1) < 1e-12
    depths = np.sort(thick.frame.to_local(thick.mesh.points[axis])[:, 2])
    spacing = np.diff(depths)
    ahead = (depths[:-1] >= 3.0 - 1e-9) & (depths[1:] <= 4.0 + 1e-9)
    assert spacing[ahead].max() <= Resolution().ligament_mm * 1.2
    assert spacing[depths[:-1] >= 4.5].min() > 2 * Resolution().ligament_mm
    assert len(depths) < 3.0 / Resolution().ligament_mm + 25


def test_tilted_top_keeps_the_hole_exact():
    """A top surface tilted by 20° across the drill axis: the wall and cone stay exact, the
    top is followed, the mesh is still conforming."""
    slope = np.tan(np.radians(20))
    hole = hole_mesh(HoleFrame.along([0, 0, 0], [0, 0, 1]), DIAMETER, POINT_ANGLE, 6.0, [3.0, 4.5],
                     top=lambda xy: slope * xy[:, 0], bottom=lambda xy: (6.0 + slope * xy[:, 0], np.ones(len(xy), bool)))
    local = hole.frame.to_local(hole.mesh.points)
    r, zeta = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
    np.testing.assert_allclose(zeta[hole.faces["top"]], slope * local[hole.faces["top"], 0], atol=1e-9)
    assert signed_volumes(hole.mesh.points, hole.mesh.tets).min() > 0
    st = hole.at_station(1)
    cone = st.faces["hole_bottom"]
    np.testing.assert_allclose(zeta[cone], 4.5 - CONE + (RADIUS - r[cone]) * CONE / RADIUS, atol=1e-9)
    np.testing.assert_allclose(r[st.faces["hole_wall"]], RADIUS, rtol=1e-12)
    _, counts = np.unique(faces_of(st.mesh.tets), axis=0, return_counts=True)
    assert counts.max() == 2


def test_bad_inputs_are_user_errors():
    frame = HoleFrame.along([0, 0, 0], [0, 0, 1])
    flat = lambda xy: np.zeros(len(xy))  # noqa: E731
    deep = lambda xy: (np.full(len(xy), 3.0), np.ones(len(xy), bool))  # noqa: E731
    with pytest.raises(UserError, match="increasing"):
        hole_mesh(frame, DIAMETER, POINT_ANGLE, 6.0, [2.0, 1.0], flat, deep)
    with pytest.raises(UserError, match="submodel radius"):
        hole_mesh(frame, DIAMETER, POINT_ANGLE, 1.0, [2.0], flat, deep)
    with pytest.raises(UserError, match="no bone"):
        hole_mesh(frame, DIAMETER, POINT_ANGLE, 6.0, [2.0], flat, lambda xy: (np.zeros(len(xy)), np.ones(len(xy), bool)))
    with pytest.raises(UserError, match="station 7"):
        plate(THICKNESS, TIPS).at_station(7)


def test_a_material_interface_is_followed_by_element_faces_beside_the_hole():
    """A cortex whose inner surface ζ_I = 3.3 + 0.08 x + 0.03 y² lies between two station
    corners (0.65 and 2.65 mm, tips 2, 4, 6 mm): on and outside the hole circle every column
    has a vertex on it, so the faces between cortical and cancellous cells lie on it there;
    the stations' holes are the same as without it, to round-off."""
    from femstudy.femur_mesh import CANCELLOUS_DISTAL, CORTICAL

    plain, hole = layered_plate(follow=False), layered_plate()
    assert signed_volumes(hole.mesh.points, hole.mesh.tets).min() > 0
    local = hole.frame.to_local(hole.mesh.points)
    on = np.abs(local[:, 2] - inner_cortex(local[:, :2])) < 1e-9
    beside = hole.disk.radius >= RADIUS * (1 - 1e-12)
    assert np.all(np.isin(np.flatnonzero(beside), hole.point_column[on]))  # every column beside the hole
    tets, region = hole.mesh.tets, hole.mesh.region
    owner = np.tile(np.arange(len(tets)), 4)
    key, inverse = np.unique(faces_of(tets), axis=0, return_inverse=True)
    cortical = np.bincount(inverse.ravel(), region[owner] == CORTICAL, len(key))
    cancellous = np.bincount(inverse.ravel(), region[owner] == CANCELLOUS_DISTAL, len(key))
    interface = key[(cortical == 1) & (cancellous == 1)]
    outside = hole.disk.radius[hole.point_column[interface]].min(axis=1) >= RADIUS * (1 - 1e-12)
    assert outside.sum() > 100 and on[interface[outside]].all()
    plain_local = plain.frame.to_local(plain.mesh.points)  # without it: a staircase
    assert not np.isclose(plain_local[:, 2], inner_cortex(plain_local[:, :2]), atol=1e-3).any()
    for k, tip in enumerate((2.0, 4.0, 6.0)):
        assert hole.removed_volume_mm3(k) == pytest.approx(plain.removed_volume_mm3(k), rel=1e-12)
        cone = hole.at_station(k).faces["hole_bottom"]
        r = np.hypot(local[cone, 0], local[cone, 1])
        np.testing.assert_allclose(local[cone, 2], tip - CONE + (RADIUS - r) * CONE / RADIUS, atol=1e-9)


def test_an_interface_crossing_a_station_corner_on_the_wall_is_not_followed():
    """An inner surface tilted through the 2.65 mm corner on the hole circle (ζ_I = 2.65 + 0.9 x)
    could be followed on half of the circle only, with the layers beside the wall squeezed
    against the pinned corner: the mesh is then the one without an interface."""
    frame = HoleFrame.along([0, 0, 0], [0, 0, 1])
    flat = lambda xy: np.zeros(len(xy))  # noqa: E731
    bottom = lambda xy: (np.full(len(xy), 8.0), np.ones(len(xy), bool))  # noqa: E731
    plain = hole_mesh(frame, DIAMETER, POINT_ANGLE, 6.0, [2.0, 4.0, 6.0], flat, bottom)
    steep = hole_mesh(frame, DIAMETER, POINT_ANGLE, 6.0, [2.0, 4.0, 6.0], flat, bottom,
                      interface=lambda xy: 2.65 + 0.9 * xy[:, 0])
    np.testing.assert_array_equal(steep.layer_offsets_mm, plain.layer_offsets_mm)
    np.testing.assert_array_equal(steep.mesh.points, plain.mesh.points)
