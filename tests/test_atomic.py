"""Atomic writes: all or nothing, ordinary permissions."""

import os

import pytest

from femstudy import atomic


def test_interrupted_folder_leaves_no_result(tmp_path):
    target = tmp_path / "run"
    with pytest.raises(RuntimeError):
        with atomic.atomic_folder(target) as tmp:
            (tmp / "summary.json").write_text("{}")
            raise RuntimeError("killed")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_folder_replaces_a_previous_result_only_when_complete(tmp_path):
    target = tmp_path / "run"
    target.mkdir()
    (target / "old.txt").write_text("old")
    with atomic.atomic_folder(target) as tmp:
        (tmp / "new.txt").write_text("new")
        assert (target / "old.txt").exists()  # still the old result while writing
    assert sorted(p.name for p in target.iterdir()) == ["new.txt"]


def test_results_get_ordinary_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        atomic.write_text(tmp_path / "a.txt", "x")
        with atomic.atomic_folder(tmp_path / "run") as tmp:
            (tmp / "b.txt").write_text("y")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "run").stat().st_mode & 0o777 == 0o755
