"""Lanes (femstudy.lanes): a function runs in a forked child and its result, or its error,
comes back to the caller; without forking it runs in the caller with the same result."""

import os
import time

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from femstudy.errors import UserError
from femstudy.lanes import Lanes, can_fork

forking = pytest.mark.skipif(not can_fork(), reason="lanes fork only on Linux with two or more cores")


def blas_threads() -> list[int]:
    return sorted(pool["num_threads"] for pool in threadpool_info())


@pytest.mark.parametrize("parallel", [True, False])
def test_a_lane_returns_what_the_function_returns(parallel):
    data = np.arange(1000.0)
    with Lanes(parallel) as lanes:
        lane = lanes.start("sum", lambda: (os.getpid(), data @ data))
        here = data.sum()
        pid, value = lane.result()
    assert value == pytest.approx(332833500.0) and here == 499500.0
    assert lane.forked == (parallel and can_fork()) and (pid != os.getpid()) == lane.forked
    assert lane.seconds >= 0


@forking
def test_lanes_run_at_once_and_share_the_threads():
    before = blas_threads()
    with Lanes() as lanes:
        inside = blas_threads()
        start = time.perf_counter()
        sleepers = [lanes.start(f"sleep {k}", lambda: time.sleep(0.5)) for k in range(2)]
        for lane in sleepers:
            lane.result()
        elapsed = time.perf_counter() - start
    assert elapsed < 0.9  # side by side, not one after the other
    assert max(inside) <= max(1, os.cpu_count() // 2)
    assert blas_threads() == before  # restored on leaving the block


@pytest.mark.parametrize("parallel", [True, False])
def test_an_error_in_a_lane_is_raised_in_the_caller(parallel):
    def fails():
        raise UserError("the bone around the drill site is too narrow")

    with Lanes(parallel) as lanes:
        lane = lanes.start("hole models", fails)
        with pytest.raises(UserError, match="too narrow") as caught:
            lane.result()
    if lane.forked:
        assert "fails" in str(caught.value.__cause__)  # the child's traceback


@forking
def test_a_lane_whose_process_dies_is_reported_not_waited_for():
    with Lanes() as lanes:
        lane = lanes.start("doomed", lambda: os._exit(3))
        with pytest.raises(RuntimeError, match="doomed process ended without a result .exit code 3"):
            lane.result()


@forking
def test_leaving_the_block_ends_a_child_still_running():
    with pytest.raises(KeyError):
        with Lanes() as lanes:
            lane = lanes.start("long", lambda: time.sleep(60))
            raise KeyError("the caller failed")
    assert not lane._process.is_alive() and lane._process.exitcode is not None


def test_the_run_command_can_keep_the_study_in_one_process():
    from femstudy.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["run", "case.toml"]).parallel is True
    assert parser.parse_args(["run", "case.toml", "--serial"]).parallel is False
