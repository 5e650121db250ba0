"""The sweep executor: local pool, Dask LocalCluster, resume after a kill."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from femstudy.sweeps.execute import Point, execute
from sweep_helpers import square

POINTS = [Point("study", {"x": x}, label=f"x={x}") for x in range(6)]


def values(records):
    return [r["result"]["value"] for r in records]


def test_local_pool_and_dask_give_identical_results(tmp_path):
    local = execute(POINTS, tmp_path / "local", square, workers=2)
    assert values(local) == [x * x for x in range(6)]
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = execute(POINTS, tmp_path / "dask", square, scheduler=cluster.scheduler_address)
    assert values(remote) == values(local)
    assert [r["point"]["id"] for r in remote] == [r["point"]["id"] for r in local]


def test_finished_points_are_not_recomputed(tmp_path):
    first = execute(POINTS[:3], tmp_path, square)
    stamps = {p.id: os.stat(tmp_path / f"{p.id}.json").st_mtime_ns for p in POINTS[:3]}
    again = execute(POINTS, tmp_path, square)
    assert values(again) == [x * x for x in range(6)]
    assert {p.id: os.stat(tmp_path / f"{p.id}.json").st_mtime_ns for p in POINTS[:3]} == stamps
    assert values(first) == values(again)[:3]


def intervals(records):
    return sorted((r["result"]["start"], r["result"]["end"]) for r in records)


def test_memory_admission_runs_oversized_points_one_at_a_time(tmp_path):
    records = execute(POINTS[:4], tmp_path / "tight", square, (0.5,), workers=2,
                      memory_bytes=lambda p: 10.0, memory_budget_bytes=15.0)
    assert values(records) == [0, 1, 4, 9]
    spans = intervals(records)
    assert all(later[0] >= earlier[1] for earlier, later in zip(spans, spans[1:]))  # never overlapping
    roomy = execute(POINTS[:4], tmp_path / "roomy", square, (0.5,), workers=2,
                    memory_bytes=lambda p: 10.0, memory_budget_bytes=25.0)
    spans = intervals(roomy)
    assert any(later[0] < earlier[1] for earlier, later in zip(spans, spans[1:]))  # two at a time


KILL_SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
from femstudy.sweeps.execute import Point, execute
from sweep_helpers import square
points = [Point("study", {{"x": x}}, label=f"x={{x}}") for x in range(8)]
execute(points, {folder!r}, square, (0.4,))
"""


def test_killed_sweep_resumes_without_recomputing(tmp_path):
    folder = tmp_path / "points"
    script = KILL_SCRIPT.format(tests=os.path.dirname(__file__), folder=str(folder))
    proc = subprocess.Popen([sys.executable, "-c", script], start_new_session=True)
    deadline = time.time() + 60
    while time.time() < deadline and len(list(folder.glob("*.json"))) < 3:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done_before = {p.name: p.stat().st_mtime_ns for p in folder.glob("*.json")}
    assert 3 <= len(done_before) < 8
    for p in folder.glob("*.json"):
        json.loads(p.read_text())  # every file present is complete
    points = [Point("study", {"x": x}, label=f"x={x}") for x in range(8)]
    records = execute(points, folder, square)
    assert values(records) == [x * x for x in range(8)]
    after = {p.name: p.stat().st_mtime_ns for p in folder.glob("*.json")}
    assert all(after[name] == stamp for name, stamp in done_before.items())
