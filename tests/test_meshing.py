"""Femur meshing end to end: the built-in femur and the TLEM2 CT femur, coarse meshes.

One cold build per femur per session (TetWild tens of seconds each), shared by all tests;
cache behaviour is tested against that entry without running TetWild again.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from conftest import TLEM2_FEMUR, assert_clean_failure, run_cli
from femstudy.casefile import parse_case
from femstudy.femur_mesh import CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL
from femstudy.meshing import cache, landmarks, model as model_module, tetra
from femstudy.study.femur import femur_model, femur_spec

SIZE_MM = 16.0  # coarse: seconds of TetWild, not minutes; the drill site is refined to 1 mm anyway
CASE = """
name = "builtin-coarse"
[site]
position = 0.5
direction = "anterior"
"""


@pytest.fixture(scope="session")
def cache_dir(mesh_cache):
    return mesh_cache


def _build(text, cache_dir, size=SIZE_MM):
    case = parse_case(text)
    return case, femur_model(case, cache_dir, size)


@pytest.fixture(scope="session")
def builtin(cache_dir):
    return _build(CASE, cache_dir)


@pytest.fixture(scope="session")
def tlem2(cache_dir):
    if not TLEM2_FEMUR.is_file():
        pytest.skip(f"TLEM2 femur not found at {TLEM2_FEMUR}")
    text = f'name = "tlem2"\n[geometry]\nsurface = "{TLEM2_FEMUR.as_posix()}"\n'
    return _build(text, cache_dir)


@pytest.fixture(params=["builtin", "tlem2"])
def any_model(request):
    if request.param == "tlem2" and not TLEM2_FEMUR.is_file():
        pytest.skip(f"TLEM2 femur not found at {TLEM2_FEMUR}")
    return request.getfixturevalue(request.param)


# -- the mesh itself ---------------------------------------------------------------------

def test_tet_volume_is_surface_minus_canal_within_1_percent(any_model):
    _, m = any_model
    s = m.stats
    vol = tetra.signed_volumes(m.mesh.points, m.mesh.tets)
    assert vol.sum() == pytest.approx(s["surface_volume_mm3"] - s["canal_volume_mm3"], rel=0.01)
    assert s["canal_volume_mm3"] > 0.05 * s["surface_volume_mm3"]  # a real canal was carved


def test_tets_positive_and_conforming(any_model):
    """Every tet positively oriented; every face shared by at most two tets; the boundary is
    two closed surfaces (periosteal and canal wall) in which every edge has two faces."""
    _, m = any_model
    assert (tetra.signed_volumes(m.mesh.points, m.mesh.tets) > 0).all()
    t = m.mesh.tets
    faces = np.sort(np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]]), axis=1)
    _, counts = np.unique(faces, axis=0, return_counts=True)
    assert counts.max() == 2
    boundary = landmarks.boundary_faces(m.mesh)
    edges = np.sort(np.concatenate([boundary[:, [0, 1]], boundary[:, [1, 2]], boundary[:, [2, 0]]]), axis=1)
    _, edge_counts = np.unique(edges, axis=0, return_counts=True)
    assert (edge_counts == 2).all()
    outer = landmarks.outer_faces(m.mesh, m.frame)
    assert 0 < len(outer) < len(boundary)  # the canal wall is the rest


def test_all_three_regions_present_and_canal_empty(any_model):
    import pyvista as pv

    _, m = any_model
    assert set(np.unique(m.mesh.region)) == {CORTICAL, CANCELLOUS_PROXIMAL, CANCELLOUS_DISTAL}
    for name, r in m.stats["regions"].items():
        assert r["tets"] > 100 and r["volume_mm3"] > 10_000, name
    grid = pv.UnstructuredGrid({10: m.mesh.tets}, m.mesh.points)
    mid_axis = m.canal_axis[len(m.canal_axis) // 2]  # the canal's centreline at mid-length
    assert abs(m.frame.fraction(mid_axis) - 0.5) < 0.01
    assert grid.find_containing_cell(mid_axis) == -1
    # proximal cancellous bone lies above the canal, distal below
    c = m.mesh.points[m.mesh.tets].mean(axis=1)
    s = m.frame.fraction(c)
    assert s[m.mesh.region == CANCELLOUS_PROXIMAL].max() < 0.5 < s[m.mesh.region == CANCELLOUS_DISTAL].min()


def test_cortical_thickness_at_midshaft_within_one_element(any_model):
    """The requested 6 mm, ± the edge length of the tets the drill axis crosses."""
    case, m = any_model
    site = m.site
    x = m.mesh.points[m.mesh.tets]
    c = x.mean(axis=1)
    rel = c - site.entry_point
    along = rel @ site.direction
    off_axis = np.linalg.norm(rel - np.outer(along, site.direction), axis=1)
    crossed = (off_axis < 1.5) & (along > 0) & (along < 8) & (m.mesh.region == CORTICAL)
    edges = np.linalg.norm(x[crossed][:, [0, 0, 0, 1, 1, 2]] - x[crossed][:, [1, 2, 3, 2, 3, 3]], axis=2)
    local = float(np.median(edges))
    assert local < 1.5  # the site is refined
    assert abs(site.cortical_thickness_mm - case.geometry.cortex.midshaft_mm) <= local


def test_quality_thresholds(any_model):
    _, m = any_model
    q = m.quality
    assert q["min_dihedral_deg"] > 5.0
    assert q["radius_ratio_min"] > 0.05
    assert q["n_poor"] <= 0.001 * q["n_tets"]
    assert q["radius_ratio_percentiles"]["50"] > 0.6
    assert sum(q["radius_ratio_histogram"]["counts"]) == m.mesh.n_tets


def test_drill_site_refined_on_the_outer_surface(any_model):
    _, m = any_model
    s, f = m.site, m.frame
    assert m.stats["site_facets_in_drill_disk"] >= 6  # the r = 1.35 mm load disk spans several facets
    assert m.stats["site_edge_mm"] < 1.3
    assert np.allclose(s.direction, -f.anterior, atol=1e-12)  # "anterior": enters the anterior cortex
    assert s.outward_normal @ -s.direction > np.cos(np.radians(25))
    assert abs(f.fraction(s.entry_point) - 0.5) < 0.005
    outer = landmarks.outer_faces(m.mesh, f)
    nearest = np.linalg.norm(m.mesh.points[np.unique(outer)] - s.entry_point, axis=1).min()
    assert nearest < 1.0  # on the surface, among its facets


def test_clamps_select_whole_end_caps(any_model):
    """Exactly the outer-surface nodes within clamps.length_mm of each end; the facets with all
    nodes clamped cover the surface's end caps but for the band of facets crossing the cut."""
    from femstudy.meshing.surface import read_surface

    case, m = any_model
    f, cl = m.frame, m.clamps
    h = m.mesh.points @ f.up
    outer = landmarks.outer_faces(m.mesh, f)
    on_surface = np.zeros(m.mesh.n_points, bool)
    on_surface[outer.ravel()] = True
    length = case.clamps.length_mm
    surface = read_surface(m.stats["surface_file"]).scaled(f.scale_to_mm).polydata()
    for mask, sign, end in ((cl.proximal, 1, h[on_surface].max()), (cl.distal, -1, h[on_surface].min())):
        assert (mask == (on_surface & (sign * (h - end) >= -length))).all()
        x = m.mesh.points[outer[mask[outer].all(axis=1)]]
        clamped_area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum()
        cap = surface.clip(normal=-sign * f.up, origin=f.up * (end - sign * length))
        assert 0.7 < clamped_area / cap.area < 1.02  # facets straddling the cut (16 mm mesh) are not clamped
    assert not (cl.proximal & cl.distal).any()


def test_frame_detected(builtin):
    _, m = builtin
    f = m.frame
    assert (f.units, f.side, f.overridden) == ("mm", "left", [])
    assert f.length_mm == pytest.approx(455, abs=3)
    # the generator's frame: +z proximal, +y anterior, +x medial (left femur)
    assert f.up @ [0, 0, 1] > 0.99 and f.anterior @ [0, 1, 0] > 0.99 and f.medial @ [1, 0, 0] > 0.99


def test_tlem2_detected_as_right_femur_in_mm(tlem2):
    _, m = tlem2
    f = m.frame
    assert (f.units, f.side) == ("mm", "right")
    assert f.length_mm == pytest.approx(415, abs=3)
    # TLEM2 uses the ISB frame: x anterior, y proximal, z to the right (lateral for a right femur)
    assert f.up @ [0, 1, 0] > 0.99 and f.anterior @ [1, 0, 0] > 0.95 and f.medial @ [0, 0, -1] > 0.95


# -- cache -------------------------------------------------------------------------------

@pytest.fixture
def forbid_tetwild(cache_dir, monkeypatch):
    """Fail the test if TetWild runs; builds read the session cache."""

    def no_tetwild(*args, **kwargs):
        raise AssertionError("TetWild ran although its mesh was cached")

    monkeypatch.setattr(tetra, "tetrahedralize", no_tetwild)


def test_cached_rebuild_skips_tetwild(builtin, forbid_tetwild, cache_dir):
    case, first = builtin
    again = femur_model(case, cache_dir, SIZE_MM)
    # ``first`` may itself come from the session cache; TetWild being forbidden is the check
    assert again.stats["cache_hit"]
    assert again.stats["cache_key"] == first.stats["cache_key"]
    assert np.array_equal(again.mesh.tets, first.mesh.tets) and np.array_equal(again.mesh.region, first.mesh.region)
    assert np.array_equal(again.clamps.proximal, first.clamps.proximal)
    assert again.site.cortical_thickness_mm == first.site.cortical_thickness_mm
    assert again.stats["load_or_build_seconds"] < 0.2 * first.stats["tetwild_seconds"]


def test_another_drill_site_reuses_the_tetwild_stage(builtin, forbid_tetwild, cache_dir):
    """Site refinement runs on the cached TetWild mesh: a new site costs no TetWild run."""
    _, first = builtin
    other = parse_case(CASE.replace("position = 0.5", "position = 0.3").replace('"anterior"', '"lateral"'))
    moved = femur_model(other, cache_dir, SIZE_MM)
    assert not moved.stats["cache_hit"] and moved.stats["cache_key"] != first.stats["cache_key"]
    assert np.linalg.norm(moved.site.entry_point - first.site.entry_point) > 50
    assert moved.stats["site_facets_in_drill_disk"] >= 8


def test_corrupted_cache_entry_is_reported_and_rebuilt(builtin, cache_dir, tmp_path, monkeypatch, caplog):
    case, first = builtin
    private = tmp_path / "cache"
    shutil.copytree(cache_dir / first.stats["cache_key"], private / first.stats["cache_key"])
    npz = private / first.stats["cache_key"] / "mesh.npz"
    data = bytearray(npz.read_bytes())
    data[len(data) // 2] ^= 0xFF
    npz.write_bytes(bytes(data))
    rebuilt = []

    def fake_build(*args):  # stands in for TetWild: hands back the entry's true contents
        rebuilt.append(True)
        arrays = {"points": first.mesh.points, "tets": first.mesh.tets.astype(np.int32),
                  "region": first.mesh.region, "canal_axis": first.canal_axis}
        return arrays, {"frame": first.frame.as_dict(), "quality": first.quality,
                        "stats": {k: v for k, v in first.stats.items() if k not in ("cache_hit", "cache_key")}}

    monkeypatch.setattr(model_module, "_build", fake_build)
    with caplog.at_level("WARNING", logger="femstudy"):
        again = femur_model(case, private, SIZE_MM)
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert rebuilt and not again.stats["cache_hit"]
    assert len(warnings) == 1 and "corrupted" in warnings[0] and "rebuilding" in warnings[0]
    assert cache.load(first.stats["cache_key"], private) is not None  # a good entry again


def test_interrupted_build_leaves_no_entry(tmp_path, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(tetra, "tetrahedralize", interrupted)
    with pytest.raises(KeyboardInterrupt):
        femur_model(parse_case(CASE), tmp_path, SIZE_MM)
    assert not [p for p in tmp_path.iterdir() if not p.name.startswith(".")]


def test_cache_key_follows_mesh_parameters_only():
    base = parse_case(CASE)

    def key(text, size=SIZE_MM):
        return cache.cache_key({"surface_sha256": "x", **model_module.mesh_parameters(femur_spec(parse_case(text)),
                                                                                       size)})

    k0 = key(CASE)
    assert key(CASE + "[clamps]\nlength_mm = 30\n") == k0  # clamps do not change the mesh
    assert key(CASE + "[drilling]\nfeed_mm_s = 1.0\n") == k0
    assert key(CASE, size=8.0) != k0
    assert key(CASE + "[geometry.cortex]\nmidshaft_mm = 5\n") != k0
    assert key(CASE.replace("0.5", "0.4")) != k0
    assert key(CASE + "[drill]\ndiameter_mm = 3.2\n") != k0  # the drill's radius sets the refined core
    assert base.mesh.refine == "site"


# -- command line ------------------------------------------------------------------------

def test_mesh_command_writes_report_and_picture(builtin, cache_dir, tmp_path):
    case, m = builtin
    case_file = tmp_path / "case.toml"
    case_file.write_text(CASE)
    out = tmp_path / "out"
    proc = run_cli("mesh", str(case_file), "--mesh-size", str(SIZE_MM), "--out", str(out),
                   env={"FEMSTUDY_CACHE": str(cache_dir)})
    assert proc.returncode == 0, proc.stderr
    assert "loaded cached mesh" in proc.stderr and "left femur" in proc.stdout
    assert {p.name for p in out.iterdir()} == {"mesh.vtu", "quality.json", "quality.txt", "frame.json",
                                              "landmarks.json", "mesh.png", ".femstudy.json"}  # the marker
    report = json.loads((out / "quality.json").read_text())
    assert report["stats"]["n_tets"] == m.mesh.n_tets and report["stats"]["cache_hit"] is True
    frame = json.loads((out / "frame.json").read_text())
    assert frame["side"] == "left" and frame["units"] == "mm"
    assert json.loads((out / "landmarks.json").read_text())["site"]["cortical_thickness_mm"] == pytest.approx(
        m.site.cortical_thickness_mm)
    assert (out / "mesh.png").stat().st_size > 100_000
    import meshio

    vtu = meshio.read(out / "mesh.vtu")
    assert len(vtu.cells_dict["tetra"]) == m.mesh.n_tets
    assert set(np.unique(vtu.cell_data["region"][0])) == {1, 2, 3}


@pytest.mark.parametrize("setup, message", [
    ("empty", "is empty"),
    ("garbage", "cannot read surface file"),
    ("open", "is not closed (3 boundary edges)"),
    ("two", "2 separate shells"),
    ("missing", "does not exist"),
    ("tiny", "cannot tell the units"),
])
def test_bad_surfaces_give_one_clear_line(tmp_path, setup, message):
    import pyvista as pv

    surface = tmp_path / "bone.stl"
    if setup == "empty":
        surface.write_bytes(b"")
    elif setup == "garbage":
        surface.write_bytes(b"\x00\x01 not a surface " * 40)
    elif setup == "open":  # femur-sized (300 mm), so that its units are told and its topology is judged
        box = pv.Box().triangulate().scale(150.0)
        pv.PolyData.from_regular_faces(box.points, box.regular_faces[1:]).save(surface)
    elif setup == "two":
        pv.Sphere().merge(pv.Sphere(center=(3, 0, 0))).scale(100.0).save(surface)
    elif setup == "tiny":
        pv.Cylinder(radius=0.5, height=3.0).triangulate().clean().save(surface)
    case_file = tmp_path / "case.toml"
    case_file.write_text(f'name = "bad"\n[geometry]\nsurface = "{surface.name}"\n')
    proc = run_cli("mesh", str(case_file), "--quiet", env={"FEMSTUDY_CACHE": str(tmp_path / "cache")})
    assert proc.returncode == 2
    assert_clean_failure(proc, message)
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_repairs_are_stated(tmp_path):
    """Inward-facing triangles are turned outwards and said so."""
    import pyvista as pv

    from femstudy.meshing.builtin_femur import BUILTIN_STL
    from femstudy.meshing.surface import read_surface

    flipped = pv.read(BUILTIN_STL)
    flipped.flip_faces(inplace=True)
    flipped.save(tmp_path / "flipped.ply")
    surf = read_surface(tmp_path / "flipped.ply")
    assert surf.repairs == ["turned inward-facing triangles outwards"]
    assert surf.volume == pytest.approx(read_surface(BUILTIN_STL).volume, rel=1e-9)


def test_the_command_line_reads_the_cache_folder_from_the_environment(tmp_path):
    from femstudy.cli import Settings

    assert Settings.from_environment({}).cache_dir == cache.DEFAULT_CACHE_DIR
    assert Settings.from_environment({"FEMSTUDY_CACHE": str(tmp_path)}).cache_dir == tmp_path


def test_a_wider_drill_is_refined_and_loaded_at_its_own_radius(builtin, forbid_tetwild, cache_dir):
    """A 3.2 mm drill: the site is refined to the site size over twice its 1.6 mm radius, and
    the load patch the study builds covers π · 1.6² (the radius comes from the case, not a constant)."""
    from femstudy import fe
    from femstudy.meshing.refine import LONGEST_PER_TARGET

    case = parse_case(CASE + "[drill]\ndiameter_mm = 3.2\n")
    model = femur_model(case, cache_dir, SIZE_MM)
    assert model.stats["drill_radius_mm"] == pytest.approx(1.6)
    x = model.mesh.points[model.mesh.tets]
    centroid_distance = np.linalg.norm(x.mean(axis=1) - model.site.entry_point, axis=1)
    edges = np.linalg.norm(x[:, [0, 0, 0, 1, 1, 2]] - x[:, [1, 2, 3, 2, 3, 3]], axis=2).max(axis=1)
    core = centroid_distance < 2 * 1.6 - case.mesh.site_size_mm  # whole tets inside the refined core
    assert core.sum() > 50 and edges[core].max() <= LONGEST_PER_TARGET * case.mesh.site_size_mm + 1e-9
    system = fe.assemble(model.mesh, order=1)
    patch = fe.drill_patch(system, model.site, radius_mm=case.drill.diameter_mm / 2)
    assert patch.area_mm2 == pytest.approx(np.pi * 1.6 ** 2, rel=0.1)


@pytest.mark.parametrize("offset", [0, 2 ** 21], ids=["keyed", "beyond-keys"])
def test_faces_of_two_tets_sharing_one(offset):
    """Two tets glued on face (1, 2, 3): six boundary faces pointing outwards, one interface
    face between their regions; the same with vertex numbers past the face keys' range."""
    from femstudy.femur_mesh import TetMesh

    points = np.zeros((offset + 5, 3))
    points[offset:] = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]
    tets = np.array([[0, 1, 2, 3], [4, 3, 2, 1]]) + offset
    mesh = TetMesh(points, tets, np.array([CORTICAL, CANCELLOUS_DISTAL], np.int8))
    boundary = landmarks.boundary_faces(mesh)
    assert len(boundary) == 6 and not any(set(f) == {offset + 1, offset + 2, offset + 3} for f in boundary)
    p = points[boundary]
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    centre = points[offset:].mean(axis=0)
    assert (np.einsum("ij,ij->i", normals, p.mean(axis=1) - centre) > 0).all()  # outwards (a convex union)
    faces, codes = landmarks.region_interface(mesh, CORTICAL)
    assert [set(f) for f in faces] == [{offset + 1, offset + 2, offset + 3}] and list(codes) == [CANCELLOUS_DISTAL]


def test_the_ray_locator_finds_the_cells_pyvistas_locator_finds(any_model):
    """femstudy.meshing.ray_cells against pyvista's cell locator (an independent implementation)
    along 40 random chords of the femur, 0.05 mm apart: the same inside/outside and regions,
    except where pyvista's tolerance takes a point just outside a tet (barycentric coordinate
    down to −1e-3; ours counts a point inside within 1e-10) for inside it: at the bone's surface,
    or at a region's boundary (then it names the neighbour's region)."""
    import pyvista as pv

    from femstudy.meshing.ray_cells import cells_along

    _, m = any_model
    grid = pv.UnstructuredGrid({10: m.mesh.tets}, m.mesh.points)
    rng = np.random.default_rng(7)
    lo, hi = m.mesh.points.min(axis=0), m.mesh.points.max(axis=0)
    s = np.arange(0.025, 80.0, 0.05)
    inside, differ = 0, 0
    for _ in range(40):
        start = lo + rng.random(3) * (hi - lo)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        points = start + np.outer(s, direction)
        ours = cells_along(m.mesh, start, direction, s)
        theirs = np.asarray(grid.find_containing_cell(points)).reshape(-1)
        found = (ours >= 0) & (theirs >= 0)
        regions_differ = found & (m.mesh.region[np.maximum(ours, 0)] != m.mesh.region[np.maximum(theirs, 0)])
        for k in np.flatnonzero(((ours >= 0) != (theirs >= 0)) | regions_differ):
            assert theirs[k] >= 0  # only pyvista's tolerance takes in more
            corners = m.mesh.points[m.mesh.tets[theirs[k]]]
            lam = np.linalg.solve((corners[1:] - corners[0]).T, points[k] - corners[0])
            assert min(lam.min(), 1 - lam.sum()) > -1e-3
            differ += 1
        inside += int(found.sum())
    assert inside > 1000 and differ <= 0.002 * inside  # the chords do cross bone


def test_a_second_size_reuses_the_surfaces_regions(tmp_path, monkeypatch, caplog):
    """Builds of one surface at sizes that simplify it alike (a sweep's sizes, its remeshes)
    read it and build its region fields once; TetWild is stopped right after."""
    from femstudy.meshing import regions

    class Stop(Exception):
        pass

    def no_tetwild(*args, **kwargs):
        raise Stop

    fields_built = []
    real_fields = regions.build_fields
    monkeypatch.setattr(regions, "build_fields", lambda *a, **k: fields_built.append(1) or real_fields(*a, **k))
    monkeypatch.setattr(tetra, "tetrahedralize", no_tetwild)
    monkeypatch.setattr(model_module, "_last_regions", {})
    case = parse_case(CASE)
    with caplog.at_level("INFO", logger="femstudy"):
        for size in (16.0, 24.0):
            with pytest.raises(Stop):
                femur_model(case, tmp_path, size)
    assert len(fields_built) == 1 and "reusing this surface's frame and region fields" in caplog.text


def test_the_regions_key_follows_the_surface_geometry_and_edge_only():
    from femstudy.meshing.model import regions_key, surface_edge_mm, surface_file

    def key(text, size):
        spec = femur_spec(parse_case(text))
        return regions_key(spec, surface_file(spec, cache.DEFAULT_CACHE_DIR), surface_edge_mm(size))

    k0 = key(CASE, 16.0)
    assert key(CASE, 24.0) == k0  # both simplified to 8 mm edges
    assert key(CASE.replace("position = 0.5", "position = 0.3"), 16.0) == k0  # the site is not in it
    assert key(CASE, 8.0) != k0
    assert key(CASE + "[geometry.cortex]\nmidshaft_mm = 5.0\n", 16.0) != k0
