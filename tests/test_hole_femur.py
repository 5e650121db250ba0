"""Column tops, bottoms and regions by ray casting on a global mesh: a hollow tube drilled
radially, the femoral shaft's simplest stand-in, where every depth is known exactly."""

from functools import lru_cache

import numpy as np
import pytest

from hole_cases import CONE, DIAMETER, POINT_ANGLE, RADIUS
from femstudy.errors import UserError
from femstudy.fe.geometry import tube_mesh
from femstudy.femur_mesh import CANCELLOUS_DISTAL, CORTICAL, TetMesh
from femstudy.hole import HoleFrame, hole_mesh
from femstudy.hole.femur import femur_columns
from femstudy.meshing.landmarks import boundary_faces
from femstudy.meshing.tetra import signed_volumes

R_OUT, R_IN, N_AROUND = 14.0, 6.5, 96
#: a 96-gon's chords lie up to R(1 − cos(π/96)) = 7.5 µm inside the outer circle (radially)
FACETING = R_OUT * (1 - np.cos(np.pi / N_AROUND))


@lru_cache(maxsize=None)
def tube():
    mesh = tube_mesh(60.0, R_OUT, R_IN, 3, N_AROUND, 30)
    centroid = mesh.points[mesh.tets].mean(axis=1)
    region = np.where(centroid[:, 2] > 30.0, CORTICAL, CANCELLOUS_DISTAL).astype(np.int8)  # two regions
    mesh = TetMesh(mesh.points, mesh.tets, region)
    boundary = boundary_faces(mesh)
    outer = boundary[np.hypot(*mesh.points[boundary].mean(axis=1)[:, :2].T) > (R_OUT + R_IN) / 2]
    return mesh, outer


def frame():
    """Entering the top of the tube (a vertex of its 96-gon) at mid-length, drilling along −y."""
    return HoleFrame.along([0.0, R_OUT, 30.0], [0.0, -1.0, 0.0])


def lateral_offset(columns, xy):
    """Distance of each column from the tube's yz plane (its global x) [mm]."""
    return np.abs(columns.frame.to_global(np.column_stack([xy, np.zeros(len(xy))]))[:, 0])


def test_columns_meet_the_outer_surface_and_exit_into_the_canal():
    mesh, outer = tube()
    columns = femur_columns(mesh, outer, frame(), depth_cap_mm=20.0)
    rng = np.random.default_rng(3)
    xy = rng.uniform(-5.5, 5.5, (40, 2))
    x = lateral_offset(columns, xy)
    top = columns.top(xy)
    slant = R_OUT / np.sqrt(R_OUT ** 2 - x ** 2)  # a radial sag seen along the ray
    np.testing.assert_allclose(top, R_OUT - np.sqrt(R_OUT ** 2 - x ** 2), atol=FACETING * slant.max() + 1e-9)
    bottom, free = columns.bottom(xy)
    assert free.all()
    inner_faceting = R_IN * (1 - np.cos(np.pi / N_AROUND)) * R_IN / np.sqrt(R_IN ** 2 - x ** 2)
    np.testing.assert_allclose(bottom, R_OUT - np.sqrt(R_IN ** 2 - x ** 2), atol=inner_faceting.max() + 1e-9)


def test_a_depth_cap_in_solid_bone_is_a_cut():
    mesh, outer = tube()
    columns = femur_columns(mesh, outer, frame(), depth_cap_mm=4.0)
    xy = np.array([[0.0, 0.0], [2.0, 3.0]])
    bottom, free = columns.bottom(xy)
    assert not free.any()
    np.testing.assert_allclose(bottom - columns.top(xy), 4.0, rtol=1e-12)


def test_local_mesh_of_a_tube_wall():
    mesh, outer = tube()
    columns = femur_columns(mesh, outer, frame(), depth_cap_mm=20.0)
    hole = hole_mesh(columns.frame, DIAMETER, POINT_ANGLE, 5.0, [3.0, 5.0, 9.5], columns.top, columns.bottom,
                     columns.region)
    assert signed_volumes(hole.mesh.points, hole.mesh.tets).min() > 0
    assert set(np.unique(hole.mesh.region)) == {CORTICAL, CANCELLOUS_DISTAL}  # the global regions carried over
    local = hole.frame.to_local(hole.mesh.points)
    centroid = hole.mesh.points[hole.mesh.tets].mean(axis=1)
    np.testing.assert_array_equal(hole.mesh.region == CORTICAL, centroid[:, 2] > 30.0)
    assert len(hole.faces["cut_bottom"]) == 0 and len(hole.faces["bottom_free"]) > 0
    radius = np.hypot(*hole.mesh.points[hole.faces["bottom_free"]].reshape(-1, 3)[:, [0, 1]].T)
    np.testing.assert_allclose(radius, R_IN, atol=0.01)  # on the canal wall
    st = hole.at_station(1)
    cone = st.faces["hole_bottom"]
    r = np.hypot(local[cone, 0], local[cone, 1])
    np.testing.assert_allclose(local[cone, 2], 5.0 - CONE + (RADIUS - r) * CONE / RADIUS, atol=1e-9)
    assert len(hole.at_station(2).faces["hole_bottom"]) == 0  # 9.5 mm tip: through the 7.5 mm wall


def test_columns_off_the_bone_are_user_errors():
    mesh, outer = tube()
    columns = femur_columns(mesh, outer, frame(), depth_cap_mm=20.0)
    with pytest.raises(UserError, match="miss the bone"):
        columns.top(np.array([[0.0, 0.0], [0.0, 20.0]]))
    with pytest.raises(UserError, match="depth cap"):
        femur_columns(mesh, outer, frame(), depth_cap_mm=0.0)


def test_smoothed_columns_are_the_gaussian_blur_of_the_tube():
    """A Gaussian of standard deviation σ blurs a depth profile f(x) to f + σ² f''/2 (+ O(σ⁴));
    the tube's top f = R − √(R² − x²) and canal f = R − √(r² − x²) are smooth, so the smoothed
    columns must follow that to within the faceting and the next-order term."""
    from femstudy.hole.femur import smooth_columns

    mesh, outer = tube()
    sigma = 0.6
    smooth = smooth_columns(femur_columns(mesh, outer, frame(), depth_cap_mm=20.0), 5.0, sigma)
    rng = np.random.default_rng(5)
    xy = rng.uniform(-3.0, 3.0, (30, 2))
    x = lateral_offset(smooth.raw, xy)
    top = smooth.top(xy)
    bottom, free = smooth.bottom(xy)
    assert free.all()
    for depth, radius in ((top, R_OUT), (bottom, R_IN)):
        curvature = radius ** 2 / (radius ** 2 - x ** 2) ** 1.5
        expected = R_OUT - np.sqrt(radius ** 2 - x ** 2) + sigma ** 2 / 2 * curvature
        np.testing.assert_allclose(depth, expected, atol=0.005 + 0.1 * sigma ** 2 / 2 * curvature.max())


def test_a_narrow_bone_shrinks_the_local_model_to_what_it_surrounds():
    """Columns more than R_OUT = 14 mm to the side of the drill axis miss the tube: a requested
    16 mm local model shrinks (0.5 mm steps) to the largest radius all of whose columns meet the
    bone, smoothing near the edge averages only the columns on bone, and a bone narrower than
    the measures need is one clear error."""
    from femstudy.hole.femur import smooth_columns
    from femstudy.hole.study import fitting_radius

    mesh, outer = tube()
    columns = femur_columns(mesh, outer, frame(), depth_cap_mm=20.0)
    assert columns.covers(np.array([[0.0, 13.0], [0.0, 14.5]])).tolist() == [True, False]
    radius = fitting_radius(columns, 16.0, 4.0)
    assert 13.0 <= radius <= R_OUT  # 14: the ring touches the 96-gon at its vertex
    smooth = smooth_columns(columns, 12.0, 1.0, spacing_mm=0.4)  # its 4σ reach passes the tube's edge: no error
    x = lateral_offset(columns, np.array([[0.0, 2.0]]))
    assert smooth.top(np.array([[0.0, 2.0]]))[0] == pytest.approx(R_OUT - np.sqrt(R_OUT ** 2 - x[0] ** 2), abs=0.05)
    with pytest.raises(UserError, match="too narrow for a local model"):
        fitting_radius(columns, 16.0, 14.5)


def test_the_inner_cortical_surface_is_smoothed_and_followed_by_the_local_mesh():
    """A tube whose outer 2.5 mm is cortex over cancellous bone (inner surface r = 11.5 mm):
    the smoothed interface is the Gaussian blur of its depth profile R_OUT − √(11.5² − x²)
    (as for the top and bottom above), the local mesh has a vertex on it on every column on
    and outside the hole circle, and near it a cell's region is the side of it its centroid is
    on, however the global mesh's cells straddle it."""
    from femstudy.hole.femur import smooth_columns

    mesh = tube_mesh(60.0, R_OUT, R_IN, 3, N_AROUND, 30)  # radial nodes at 6.5, 9, 11.5, 14 mm
    centroid = mesh.points[mesh.tets].mean(axis=1)
    split = 11.5
    region = np.where(np.hypot(centroid[:, 0], centroid[:, 1]) > split, CORTICAL, CANCELLOUS_DISTAL).astype(np.int8)
    mesh = TetMesh(mesh.points, mesh.tets, region)
    boundary = boundary_faces(mesh)
    outer = boundary[np.hypot(*mesh.points[boundary].mean(axis=1)[:, :2].T) > (R_OUT + R_IN) / 2]
    sigma = 0.6
    smooth = smooth_columns(femur_columns(mesh, outer, frame(), depth_cap_mm=20.0), 5.0, sigma)
    assert smooth.inner_code == CANCELLOUS_DISTAL
    xy = np.random.default_rng(7).uniform(-3.0, 3.0, (30, 2))
    x = lateral_offset(smooth.raw, xy)
    curvature = split ** 2 / (split ** 2 - x ** 2) ** 1.5
    expected = R_OUT - np.sqrt(split ** 2 - x ** 2) + sigma ** 2 / 2 * curvature
    np.testing.assert_allclose(smooth.interface(xy), expected, atol=0.005 + 0.1 * sigma ** 2 / 2 * curvature.max())

    hole = hole_mesh(smooth.frame, DIAMETER, POINT_ANGLE, 5.0, [2.0, 4.0], smooth.top, smooth.bottom, smooth.region,
                     interface=smooth.interface)
    assert signed_volumes(hole.mesh.points, hole.mesh.tets).min() > 0
    local = hole.frame.to_local(hole.mesh.points)
    on = np.abs(local[:, 2] - smooth.interface(local[:, :2])) < 1e-9
    beside = np.flatnonzero(hole.disk.radius >= RADIUS * (1 - 1e-12))
    assert np.all(np.isin(beside, hole.point_column[on]))
    centre = hole.frame.to_local(hole.mesh.points[hole.mesh.tets].mean(axis=1))
    above = centre[:, 2] < smooth.interface(centre[:, :2])
    np.testing.assert_array_equal(hole.mesh.region == CORTICAL, above)
