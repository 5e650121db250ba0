"""Reading a user's surface file: folders, unreadable and corrupt files, several bodies.

The same cases run through the command line in the bad-input corpus (tests/bad_inputs)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import REPO
from femstudy.casefile import GeometrySpec, load_case, parse_case
from femstudy.errors import UserError
from femstudy.meshing import surface
from femstudy.meshing.frame import build_frame
from femstudy.meshing.model import mesh_parameters
from femstudy.study.femur import femur_spec
from femstudy.meshing.surface import read_surface

CORPUS = REPO / "tests" / "bad_inputs" / "surfaces"


def test_a_folder_is_named_as_such_listing_the_surfaces_in_it(tmp_path):
    (tmp_path / "scan").mkdir()
    (tmp_path / "scan" / "femur_r.stl").write_bytes((CORPUS / "femur_with_patella.stl").read_bytes())
    with pytest.raises(UserError, match=r"scan is a folder, not a surface file \(it holds femur_r.stl: name one of them\)"):
        read_surface(tmp_path / "scan")
    case = tmp_path / "case.toml"
    case.write_text('name = "c"\n[geometry]\nsurface = "scan"\n')
    with pytest.raises(UserError, match=r"case.toml:3: geometry.surface: .*scan is a folder, not a surface file"):
        load_case(case)


def test_an_unreadable_file_names_the_systems_complaint(tmp_path, monkeypatch):
    path = tmp_path / "femur.stl"
    path.write_bytes((CORPUS / "femur_with_patella.stl").read_bytes())

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(surface, "open", denied, raising=False)  # as root, chmod would not stop a read
    with pytest.raises(UserError, match=r"^cannot read surface file .*femur.stl: Permission denied$"):
        read_surface(path)


@pytest.mark.parametrize("name, message", [
    ("truncated_binary.stl", "it is cut short or not an STL file (it holds 100 of the 744 triangles"),
    ("cut_ascii.stl", "the ASCII STL is cut short"),
    ("garbled_ascii.stl", "could not convert string to float: '4.5O'"),
    ("truncated.ply", "buffer size must be a multiple of element size (is it a complete PLY file?)"),
])
def test_a_corrupt_file_gives_the_readers_complaint(name, message):
    with pytest.raises(UserError) as caught:
        read_surface(CORPUS / name)
    assert str(caught.value).startswith(f"cannot read surface file {CORPUS / name}: ") and message in str(caught.value)


def test_a_binary_stl_whose_header_starts_with_solid_is_still_binary(tmp_path):
    raw = bytearray((CORPUS / "femur_with_patella.stl").read_bytes())
    raw[:80] = b"solid exported by a CAD program".ljust(80)
    (tmp_path / "femur.stl").write_bytes(bytes(raw))
    with pytest.raises(UserError, match="2 separate shells"):  # read in full, not taken for a cut ASCII file
        read_surface(tmp_path / "femur.stl")


def test_several_bodies_are_listed_and_the_largest_can_be_kept():
    with pytest.raises(UserError, match=r"2 separate shells \(bodies: 600 triangles spanning 455, 144 triangles "
                                        r"spanning 44, in the file's units\); set geometry.bodies = \"largest\""):
        read_surface(CORPUS / "femur_with_patella.stl")
    surf = read_surface(CORPUS / "femur_with_patella.stl", bodies="largest")
    assert len(surf.triangles) == 600 and np.ptp(surf.points[:, 2]) == pytest.approx(455, abs=1)
    assert surf.repairs[0] == "kept the largest of 2 bodies (600 triangles spanning 455, 144 triangles spanning 44)"
    frame, _ = build_frame(surf.points, surf.triangles, GeometrySpec(bodies="largest"))
    assert frame.side == "left" and frame.up @ [0, 0, 1] > 0.99


def test_bodies_setting_leaves_the_mesh_cache_key_alone():
    one = parse_case('name = "a"\n')
    largest = parse_case('name = "a"\n[geometry]\nbodies = "largest"\n')
    assert largest.geometry.bodies == "largest"
    assert mesh_parameters(femur_spec(one), 8.0) == mesh_parameters(femur_spec(largest), 8.0)
    with pytest.raises(UserError, match=r"geometry.bodies: Input should be 'one' or 'largest'"):
        parse_case('name = "a"\n[geometry]\nbodies = "all"\n')
