"""Atomic writes: all or nothing, ordinary permissions, and never a folder femstudy did not
write (class 3 of issue #34: what femstudy replaces, it wrote)."""

import json
import os
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from femstudy import atomic
from femstudy.errors import UserError
from femstudy.writable import check_output_file, check_output_folder


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
    with atomic.atomic_folder(target) as tmp:
        (tmp / "old.txt").write_text("old")
    with atomic.atomic_folder(target) as tmp:
        (tmp / "new.txt").write_text("new")
        assert (target / "old.txt").exists()  # still the old result while writing
    assert sorted(p.name for p in target.iterdir()) == [atomic.MARKER, "new.txt"]
    assert json.loads((target / atomic.MARKER).read_text())["files"] == ["new.txt"]


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


def test_a_folder_of_the_users_is_refused_and_kept(tmp_path):
    mine = tmp_path / "mydata"
    mine.mkdir()
    (mine / "notes.txt").write_text("precious")
    with pytest.raises(UserError, match="femstudy did not write it"):
        with atomic.atomic_folder(mine):
            raise AssertionError("the work must not start")
    assert (mine / "notes.txt").read_text() == "precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mydata"]


def test_a_file_added_to_a_femstudy_result_protects_it(tmp_path):
    target = tmp_path / "run"
    with atomic.atomic_folder(target) as tmp:
        (tmp / "summary.json").write_text("{}")
    (target / "my-notes.md").write_text("mine")
    with pytest.raises(UserError, match="holds my-notes.md, which femstudy did not write"):
        check_output_folder(target)
    with pytest.raises(UserError, match="holds my-notes.md"):
        with atomic.atomic_folder(target):
            pass
    assert (target / "my-notes.md").read_text() == "mine"


def test_an_empty_folder_may_be_filled(tmp_path):
    (tmp_path / "empty").mkdir()
    with atomic.atomic_folder(tmp_path / "empty") as tmp:
        (tmp / "a.txt").write_text("a")
    assert (tmp_path / "empty" / "a.txt").is_file()


@pytest.mark.parametrize("name", [".", "..", "../..", "/"])
def test_the_working_folder_and_its_parents_are_never_outputs(tmp_path, monkeypatch, name):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    with pytest.raises(UserError, match="working folder"):
        check_output_folder(name)
    assert work.is_dir()


def test_the_cache_and_the_inputs_are_never_outputs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cache = tmp_path / ".femstudy-cache"
    cache.mkdir()
    case = tmp_path / "cases" / "c.toml"
    case.parent.mkdir()
    case.write_text("name = 'c'")
    for target, message in ((cache, "is the mesh cache"), (cache / "x", "inside the mesh cache"),
                            (tmp_path / "cases", "holds the input")):
        with pytest.raises(UserError, match=message):
            check_output_folder(target, inputs=[case], cache_dir=cache)
    with pytest.raises(UserError, match="is an input"):
        check_output_file(case, "the diagnosis", inputs=[case])
    with pytest.raises(UserError, match="it is a folder"):
        check_output_file(cache, "the diagnosis")


def test_a_file_is_not_replaced_by_a_folder(tmp_path):
    report = tmp_path / "report"
    report.write_text("my report")
    with pytest.raises(UserError, match="it exists and is a file"):
        check_output_folder(report)
    with pytest.raises(UserError, match="it exists and is a file"):
        with atomic.atomic_folder(report):
            pass
    assert report.read_text() == "my report"


def test_a_killed_writer_leaves_a_partial_folder_the_next_write_removes(tmp_path):
    """A process killed while building a folder leaves ``.run.partial-<pid>-*``; the next
    folder written beside it removes it (its process is gone and it holds femstudy's marker),
    and never a look-alike folder without the marker."""
    script = ("import os, sys\nfrom femstudy import atomic\n"
              "with atomic.atomic_folder(sys.argv[1]) as tmp:\n"
              "    (tmp / 'half.csv').write_text('x' * 1000)\n"
              "    os.kill(os.getpid(), 9)\n")
    subprocess.run([sys.executable, "-c", script, str(tmp_path / "run")])
    left = [p.name for p in tmp_path.iterdir()]
    assert len(left) == 1 and left[0].startswith(".run.partial-")
    lookalike = tmp_path / ".notes.partial-1-abc"  # a user's folder that merely looks like one
    lookalike.mkdir()
    with atomic.atomic_folder(tmp_path / "other") as tmp:
        (tmp / "a.txt").write_text("a")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".notes.partial-1-abc", "other"]


NAMES = st.text(st.sampled_from("ab.-_/"), min_size=1, max_size=6)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=NAMES, marked=st.booleans(), extra=st.booleans())
def test_any_output_name_either_writes_or_refuses_without_deleting(tmp_path_factory, name, marked, extra):
    """Property: whatever folder name is given, the user's file survives; femstudy either
    writes its folder or refuses in one line."""
    root = tmp_path_factory.mktemp("prop")
    users = root / "data" / "keep.txt"
    users.parent.mkdir()
    users.write_text("user")
    if marked:  # an earlier result of femstudy's beside it
        with atomic.atomic_folder(root / "data" / "old") as tmp:
            (tmp / "r.txt").write_text("r")
        if extra:
            (root / "data" / "old" / "mine.txt").write_text("user")
    cwd = os.getcwd()
    os.chdir(root / "data")
    try:
        with atomic.atomic_folder(name) as tmp:
            (tmp / "new.txt").write_text("new")
    except UserError as exc:
        assert "\n" not in str(exc)
    finally:
        os.chdir(cwd)
    assert users.read_text() == "user"
    if marked and extra:
        assert (root / "data" / "old" / "mine.txt").read_text() == "user"
