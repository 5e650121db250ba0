"""The preflight estimate's surface size (femstudy.study.feasibility.surface_size): measured,
kept in the cache under the file's SHA-256 only when asked (a study that passed its checks),
read back equal; a changed file is measured again."""

import json
import shutil

import pytest

from conftest import REPO
from femstudy.study import feasibility

SURFACE = REPO / "femstudy/meshing/data/femur_left_medium.stl"


def test_a_kept_surface_size_is_the_measured_one_and_follows_the_file(tmp_path, monkeypatch):
    surface = tmp_path / "femur.stl"
    shutil.copyfile(SURFACE, surface)
    cache = tmp_path / "cache"
    measured = feasibility.surface_size(surface, cache)
    assert measured == pytest.approx(feasibility.surface_size(SURFACE))   # same bytes, same size
    assert not cache.exists()                                              # reading keeps nothing
    feasibility.keep_surface_size(surface, cache)
    kept = list((cache / "surface-sizes").glob("*.json"))
    assert len(kept) == 1 and json.loads(kept[0].read_text())["length_mm"] == measured[1]

    feasibility._surface_size.cache_clear()
    monkeypatch.setattr(feasibility, "_measure_surface", lambda path: pytest.fail("measured again"))
    assert feasibility.surface_size(surface, cache) == measured              # read back, not measured

    monkeypatch.undo()
    feasibility._surface_size.cache_clear()
    data = surface.read_bytes()
    surface.write_bytes(data[:79] + bytes([data[79] ^ 1]) + data[80:])  # another binary STL header byte
    assert feasibility.surface_size(surface, cache) == pytest.approx(measured)
    feasibility.keep_surface_size(surface, cache)
    assert len(list((cache / "surface-sizes").glob("*.json"))) == 2
