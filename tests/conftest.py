"""Shared test helpers."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
#: The TLEM 2.0 CT femur (non-commercial licence: never copied into the repository). Tests that
#: need it look next to the checkout, or where $FEMSTUDY_TLEM2 points, and skip otherwise.
TLEM2_FEMUR = Path(os.environ.get("FEMSTUDY_TLEM2") or SHARED / "data" / "femur-tlem2" / "femur_r.stl")


#: Order of the heavy tests, ``pytest.mark.slow(rank=...)``: the README's main study (the default
#: case at its own settings, from the session's shared cache) first, the other heavy tests next,
#: and last of them those that run the default case again (the README's script, the study
#: example): by the time they start, the main study has kept its answers and they read them.
#: xdist's ``loadgroup`` would pin them to one worker, but with pytest 9 it groups nothing.
MAIN_STUDY, HEAVY, AFTER_MAIN_STUDY = 0, 1, 2


def pytest_collection_modifyitems(config, items):
    """The heavy tests (marked ``slow``: cold studies, the documentation's scripts) first, in
    the order of their ``rank`` (:data:`MAIN_STUDY`, :data:`HEAVY`, :data:`AFTER_MAIN_STUDY`),
    then the rest: the two xdist workers start on them at once and finish on short tests,
    instead of one worker running a three-minute study alone at the end."""
    def rank(item) -> int:
        slow = item.get_closest_marker("slow")
        return AFTER_MAIN_STUDY + 1 if slow is None else slow.kwargs.get("rank", HEAVY)

    items.sort(key=rank)


def pytest_report_header(config):
    """Say up front whether the real-femur tests will run, and how to make them."""
    if TLEM2_FEMUR.is_file():
        return f"TLEM 2.0 femur: {TLEM2_FEMUR} (its tests run)"
    return (f"TLEM 2.0 femur: not found at {TLEM2_FEMUR}; its tests skip. Put the femur there "
            "(../shared/data/femur-tlem2/femur_r.stl next to the checkout) or set FEMSTUDY_TLEM2=/path/to/femur_r.stl")


def run_cli(*args: str, cwd: Path | None = None, env: dict | None = None,
            timeout: float = 600) -> subprocess.CompletedProcess:
    """Run ``python -m femstudy ARGS`` and capture its output."""
    full_env = {**os.environ, "MPLBACKEND": "Agg", **(env or {})}
    return subprocess.run([sys.executable, "-m", "femstudy", *args], cwd=cwd, env=full_env,
                          capture_output=True, text=True, timeout=timeout)


def assert_clean_failure(proc: subprocess.CompletedProcess, expected: str) -> None:
    """A user error: non-zero exit, the expected message on stderr, no traceback."""
    assert proc.returncode != 0, proc.stdout
    assert "Traceback" not in proc.stderr, proc.stderr
    assert expected in proc.stderr, proc.stderr


@pytest.fixture
def bone_library(tmp_path, monkeypatch):
    """An empty, private folder for calibrated bone sets."""
    folder = tmp_path / "bones"
    folder.mkdir()
    monkeypatch.setenv("FEMSTUDY_BONES", str(folder))
    return folder


@pytest.fixture(scope="session")
def mesh_cache(tmp_path_factory, shared_cache):
    """One cache per test session and xdist worker, for tests that count factorisations, clear
    kept answers or expect a first run to compute: what another worker's tests keep cannot reach
    them. Its meshes need no such isolation (an entry never changes once stored): the built-in
    femur at 16 mm, which most of these tests mesh, is built once in the shared cache (a worker
    asking meanwhile waits on its build lock) and the shared cache's mesh entries are copied in,
    instead of each worker running TetWild on it again."""
    from femstudy.casefile import parse_case
    from femstudy.study.femur import femur_model

    folder = tmp_path_factory.mktemp("mesh-cache")
    femur_model(parse_case('name = "warm"\n[mesh]\nsize_mm = 16.0\n'), shared_cache)
    for entry in shared_cache.iterdir():  # complete entries only: one being written has a hidden name
        if len(entry.name) == 64 and (entry / "meta.json").is_file():
            shutil.copytree(entry, folder / entry.name)
    return folder


@pytest.fixture(scope="session")
def shared_cache(tmp_path_factory):
    """One cache for the whole session, every xdist worker included, for tests that only use
    meshes and kept answers (the documentation's scripts, the examples, the sweeps): each mesh
    is built once, however many workers ask for it at once (a second one waits on the entry's
    build lock and loads it, femstudy.meshing.cache; TetWild is not deterministic, so two builds
    of one key would differ), and an answer kept by one test serves the others."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # workers' basetemps share a parent
    folder = root / "shared-cache"
    folder.mkdir(exist_ok=True)
    return folder
