"""Meshing building blocks: the built-in surface, frame detection, distances, refinement, quality."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import REPO, TLEM2_FEMUR, assert_clean_failure, run_cli
from femstudy.casefile import CanalSpec, CortexSpec, GeometrySpec
from femstudy.errors import UserError
from femstudy.femur_mesh import TetMesh
from femstudy.meshing import refine, regions, tetra
from femstudy.meshing.builtin_femur import BUILTIN_STL
from femstudy.meshing.frame import build_frame
from femstudy.meshing.surface import read_surface


@pytest.fixture(scope="module")
def femur():
    return read_surface(BUILTIN_STL)


def test_builtin_stl_is_regenerated_bit_for_bit(tmp_path):
    out = tmp_path / "femur.stl"
    proc = run_cli("femur", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    digest = hashlib.sha256(out.read_bytes()).hexdigest()
    assert digest == hashlib.sha256(BUILTIN_STL.read_bytes()).hexdigest()
    assert (REPO / "meshes" / "femur_left_medium.stl").read_bytes() == BUILTIN_STL.read_bytes()
    assert BUILTIN_STL.stat().st_size < 1_000_000


def test_femur_command_refuses_implausible_anatomy(tmp_path):
    proc = run_cli("femur", "--out", str(tmp_path / "f.stl"), "--neck-shaft-angle-deg", "170")
    assert_clean_failure(proc, "neck-shaft angle must lie in 110-150 deg")
    assert not (tmp_path / "f.stl").exists()


def test_builtin_femur_anatomy(femur):
    """Closed single shell; length, head, mid-shaft, neck-shaft angle and anteversion as designed."""
    p = femur.points
    assert femur.repairs == []
    assert np.ptp(p[:, 2]) == pytest.approx(455, abs=1)
    # head: least-squares sphere through the points above the greater trochanter
    top = p[p[:, 2] > 440]
    A = np.column_stack([2 * top, np.ones(len(top))])
    sol, *_ = np.linalg.lstsq(A, (top ** 2).sum(axis=1), rcond=None)
    centre, radius = sol[:3], np.sqrt(sol[3] + sol[:3] @ sol[:3])
    assert 2 * radius == pytest.approx(45, abs=1.5)
    # neck-shaft angle and anteversion from the head centre and the shaft axis (x = y = 0)
    off = np.hypot(centre[0], centre[1])
    assert np.degrees(np.arctan2(centre[1], centre[0])) == pytest.approx(12, abs=1)
    neck_base_z = centre[2] - off / np.tan(np.radians(50))
    assert np.degrees(np.arctan2(off, centre[2] - neck_base_z)) == pytest.approx(50, abs=0.5)  # 180 - 130
    # mid-shaft: equivalent diameter of the cross-section about 28 mm
    ring = p[np.abs(p[:, 2] - 227.5) < 4]
    c = ring[:, :2].mean(axis=0)
    assert 2 * np.median(np.linalg.norm(ring[:, :2] - c, axis=1)) == pytest.approx(28, abs=1.5)
    # anterior bow: the mid-shaft centre lies anterior (+y) of the line through the shaft ends
    assert c[1] > 5
    assert femur.volume == pytest.approx(600_000, rel=0.05)


def _frame(surf, **overrides):
    return build_frame(surf.points, surf.triangles, GeometrySpec(**overrides))[0]


@pytest.mark.parametrize("scale, units", [(0.001, "m"), (0.1, "cm"), (1 / 25.4, "in"), (1.0, "mm")])
def test_units_and_orientation_of_a_scaled_rotated_copy(femur, scale, units):
    R = Rotation.from_euler("xyz", [35, -70, 120], degrees=True).as_matrix()
    moved = type(femur)(femur.points @ R.T * scale + 0.4 * scale, femur.triangles, "copy")
    f = _frame(moved)
    assert f.units == units and f.length_mm == pytest.approx(455, abs=2)
    assert (R.T @ f.up) @ [0, 0, 1] > 0.999
    assert (R.T @ f.anterior) @ [0, 1, 0] > 0.99
    assert f.side == "left"


def test_mirrored_femur_is_right(femur):
    mirrored = type(femur)(femur.points * [-1, 1, 1], femur.triangles[:, ::-1], "mirror")
    f = _frame(mirrored)
    assert f.side == "right" and f.medial @ [-1, 0, 0] > 0.99 and f.anterior @ [0, 1, 0] > 0.99


def test_case_overrides_win(femur):
    in_cm = type(femur)(femur.points / 10, femur.triangles, "cm")
    f = _frame(in_cm, units="cm", proximal_end="-", long_axis=(0, 0, 1), anterior=(0, -1, 0), side="right")
    assert f.units == "cm" and f.scale_to_mm == 10
    assert f.up @ [0, 0, -1] > 0.999 and f.anterior @ [0, -1, 0] > 0.999 and f.side == "right"
    assert set(f.overridden) == {"units", "proximal_end", "long_axis", "anterior", "side"}
    # a stated side alone fixes the anterior sign, the head still gives medial
    g = _frame(femur, side="right")
    assert g.side == "right" and g.anterior @ [0, -1, 0] > 0.99 and g.medial @ [1, 0, 0] > 0.99


@pytest.mark.skipif(not TLEM2_FEMUR.is_file(), reason="TLEM2 femur not available")
def test_tlem2_in_metres_and_rotated():
    surf = read_surface(TLEM2_FEMUR)
    R = Rotation.from_euler("zyx", [90, 20, -45], degrees=True).as_matrix()
    f = _frame(type(surf)(surf.points @ R.T / 1000, surf.triangles, "m"))
    assert (f.units, f.side) == ("m", "right")
    assert (R.T @ f.up) @ [0, 1, 0] > 0.99 and (R.T @ f.anterior) @ [1, 0, 0] > 0.95


def test_stated_units_that_make_no_femur_are_refused(femur):
    in_metres = type(femur)(femur.points / 1000, femur.triangles, "m")
    with pytest.raises(UserError, match=r'units = "mm" the bone is 0.45\d+ mm long.*looks like m'):
        _frame(in_metres, units="mm")


def test_a_bone_without_a_head_is_not_oriented_by_guesswork():
    import pyvista as pv

    from femstudy.meshing.surface import prepare

    cylinder = prepare(pv.Cylinder(radius=14, height=450, resolution=24).triangulate().clean(), "cylinder")
    with pytest.raises(UserError, match="cannot tell which end of the bone is proximal"):
        _frame(cylinder)


def test_unknown_units_are_a_user_error(femur):
    with pytest.raises(UserError, match="cannot tell the units"):
        _frame(type(femur)(femur.points * 5, femur.triangles, "x5"))


def test_cortical_thickness_profile():
    cortex, canal = CortexSpec(midshaft_mm=6, epiphysis_mm=2), CanalSpec()
    t = regions.thickness(np.array([0.0, 0.12, 0.22, 0.32, 0.5, 0.68, 0.78, 0.88, 1.0]), cortex, canal)
    assert t == pytest.approx([2, 2, 4, 6, 6, 6, 4, 2, 2])


def test_point_triangle_distance_against_sampling():
    rng = np.random.default_rng(7)
    tri = rng.normal(size=(40, 3, 3))
    p = 2 * rng.normal(size=(40, 3))
    d = regions.point_triangle_distance(p, tri)
    u = rng.random((20000, 2))
    u[u.sum(axis=1) > 1] = 1 - u[u.sum(axis=1) > 1]
    for i in range(40):
        a, b, c = tri[i]
        sampled = np.linalg.norm(a + u[:, :1] * (b - a) + u[:, 1:] * (c - a) - p[i], axis=1).min()
        assert d[i] <= sampled + 1e-12 and sampled - d[i] < 0.05 * np.linalg.norm(b - a)


def _cube_mesh():
    import pyvista as pv

    grid = pv.ImageData(dimensions=(5, 5, 5), spacing=(2.5, 2.5, 2.5)).to_tetrahedra()
    tets = tetra.orient(np.asarray(grid.points, float), grid.cells_dict[10].astype(np.int64))
    return TetMesh(np.asarray(grid.points, float), tets, np.ones(len(tets), np.int8))


def test_refinement_is_conforming_and_keeps_volume_and_quality():
    mesh = _cube_mesh()
    target = refine.site_target([5, 5, 10], 10.0, 0.8, 6.0, 2.0)
    fine = refine.refine(mesh, target)
    assert fine.n_tets > 4 * mesh.n_tets
    vol = tetra.signed_volumes(fine.points, fine.tets)
    assert (vol > 0).all() and vol.sum() == pytest.approx(1000.0, rel=1e-12)
    t = fine.tets
    faces = np.sort(np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]]), axis=1)
    # conforming: no face is shared by more than two tets, and the faces of only one tet are
    # exactly the cube's surface (a hanging node would leave extra, overlapping faces)
    uniq, counts = np.unique(faces, axis=0, return_counts=True)
    assert counts.max() == 2
    bf = uniq[counts == 1]
    x = fine.points[bf]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum()
    assert area == pytest.approx(600.0, rel=1e-9)
    near = np.linalg.norm(fine.points[fine.tets].mean(axis=1) - [5, 5, 10], axis=1) < 2.0
    longest = np.stack([np.linalg.norm(fine.points[t[:, i]] - fine.points[t[:, j]], axis=1)
                        for i, j in refine.EDGES], axis=1).max(axis=1)
    assert longest[near].max() <= refine.LONGEST_PER_TARGET * 0.8 + 1e-9
    q0, q1 = tetra.quality(mesh), tetra.quality(fine)
    assert q0["min_dihedral_deg"] > 45 and q1["min_dihedral_deg"] > 20 and q1["radius_ratio_min"] > 0.2


def test_quality_of_a_regular_tet():
    x = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    q = tetra.quality(TetMesh(x, tetra.orient(x, np.array([[0, 1, 2, 3]])), np.ones(1, np.int8)))
    assert q["radius_ratio_min"] == pytest.approx(1.0)
    assert q["min_dihedral_deg"] == pytest.approx(np.degrees(np.arccos(1 / 3)))
    assert q["n_poor"] == 0


def test_cortex_filling_the_bone_is_a_user_error(femur):
    from femstudy.meshing.frame import build_frame

    frame, _ = build_frame(femur.points, femur.triangles, GeometrySpec())
    with pytest.raises(UserError, match="fills the whole bone"):
        # beyond the case files' 20 mm: the regions guard on their own (a thin bone is filled by less)
        regions.build_fields(femur, frame, GeometrySpec(cortex=CortexSpec.model_construct(midshaft_mm=40,
                                                                                          epiphysis_mm=40)),
                             voxel_mm=3.0)


def test_level_surface_through_grid_nodes_is_all_triangles():
    """An octahedron |x| + |y| + |z| = 5 on a 1 mm grid passes through grid nodes: contouring
    gives collapsed triangles, which cleaning turned into lines and quadric decimation refused."""
    x = np.stack(np.meshgrid(*[np.arange(-7.0, 8)] * 3, indexing="ij"), axis=-1)
    field = 5 - np.abs(x).sum(axis=-1)
    fields = regions.RegionFields(np.full(3, -7.0), 1.0, field, field, field, np.zeros((2, 3)))
    surf = regions.level_surface(fields, "inner")
    assert surf.is_all_triangles and surf.n_lines == 0 and surf.n_verts == 0
    assert surf.volume == pytest.approx(4 / 3 * 5 ** 3, rel=1e-6)  # the octahedron, exactly
    assert surf.decimate(0.5, volume_preservation=True).n_cells > 0


def test_pinched_boundary_is_filled():
    """Two solid blocks touching along one edge only: the empty tets around that edge are
    filled with the region of the solid tets around it, and the boundary becomes manifold."""
    import pyvista as pv

    grid = pv.ImageData(dimensions=(3, 3, 2)).to_tetrahedra()
    x = np.asarray(grid.points, float)
    tets = tetra.orient(x, grid.cells_dict[10].astype(np.int64))
    c = x[tets].mean(axis=1)
    diagonal = (c[:, 0] < 1) == (c[:, 1] < 1)  # blocks (0, 0) and (1, 1) share the edge x = y = 1
    region = np.where(diagonal, np.where(c[:, 0] < 1, 2, 3), 0).astype(np.int8)
    filled = tetra._manifold_boundary(tets, region)
    assert ((filled > 0) | ~diagonal).all() and (filled[diagonal] == region[diagonal]).all()
    new = (filled > 0) & (region == 0)
    assert new.any() and (np.abs(c[new][:, :2] - 1).max(axis=1) < 1).all()  # only around the edge
    t = tets[filled > 0]
    faces = np.sort(np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]]), axis=1)
    key, counts = np.unique(faces, axis=0, return_counts=True)
    b = key[counts == 1]
    _, edge_counts = np.unique(np.sort(np.concatenate([b[:, [0, 1]], b[:, [1, 2]], b[:, [0, 2]]]), axis=1),
                               axis=0, return_counts=True)
    assert (edge_counts == 2).all()


def test_self_intersections_are_found_and_refused():
    import pyvista as pv

    from femstudy.meshing.intersections import self_intersections
    from femstudy.meshing.surface import prepare

    sphere = pv.Sphere(radius=20, theta_resolution=20, phi_resolution=20).triangulate().clean()
    points = np.asarray(sphere.points, float)
    assert len(self_intersections(points, sphere.regular_faces)) == 0
    pushed = points.copy()
    cap = pushed[:, 2] > 15
    pushed[cap, 2] = -pushed[cap, 2] - 12  # the north cap pokes out through the south pole
    assert len(self_intersections(pushed, sphere.regular_faces)) > 0
    with pytest.raises(UserError, match="the surface intersects itself"):
        prepare(pv.PolyData.from_regular_faces(pushed, sphere.regular_faces), "pushed")


def test_candidate_pairs_are_reduced_to_distinct_unordered_pairs_in_order():
    from femstudy.meshing.intersections import _unique_pairs

    rng = np.random.default_rng(7)
    pairs = rng.integers(0, 50, (5000, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    assert np.array_equal(_unique_pairs(pairs, 50), np.unique(np.sort(pairs, axis=1), axis=0))
    assert _unique_pairs(np.empty((0, 2), int), 50).shape == (0, 2)
