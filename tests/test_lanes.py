"""Lanes (femstudy.lanes): a function runs in a forked child and its result, or its error,
comes back to the caller; without forking it runs in the caller with the same result."""

import os
import sys
import time

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from femstudy.errors import UserError
from femstudy.lanes import Lanes, can_fork, cores


def forks_here() -> bool:
    """What lanes do here: fork on Linux with two or more cores."""
    return sys.platform.startswith("linux") and cores() >= 2


forking = pytest.mark.skipif(not forks_here(), reason="lanes fork only on Linux with two or more cores")


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
def test_lanes_run_at_once_and_share_the_threads(tmp_path):
    def meet(mine: str, other: str) -> bool:  # each waits for the other: only side by side do both arrive
        (tmp_path / mine).touch()
        deadline = time.monotonic() + 20
        while not (tmp_path / other).exists():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)
        return True

    before = blas_threads()
    with Lanes() as lanes:
        assert lanes.forking
        inside = blas_threads()
        pair = [lanes.start("a", lambda: meet("a", "b")), lanes.start("b", lambda: meet("b", "a"))]
        assert [lane.result() for lane in pair] == [True, True]
    assert max(inside) <= max(1, cores() // 2)
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
        assert lanes.forking  # else the function would end this process
        lane = lanes.start("doomed", lambda: os._exit(3))
        with pytest.raises(RuntimeError, match="doomed process ended without a result .exit code 3"):
            lane.result()


@forking
def test_leaving_the_block_ends_a_child_still_running_and_its_atomic_writes_clean_up(tmp_path):
    from femstudy.atomic import atomic_path

    def writes_slowly():
        with atomic_path(tmp_path / "result.npz") as part, open(part, "wb") as out:
            out.write(b"half a result")
            time.sleep(60)

    start = time.perf_counter()
    with pytest.raises(KeyError):
        with Lanes() as lanes:
            lane = lanes.start("long", writes_slowly)
            time.sleep(0.5)
            raise KeyError("the caller failed")
    assert time.perf_counter() - start < 5 and lane.exitcode == 143  # 128 + SIGTERM, not the sleep's end
    assert list(tmp_path.iterdir()) == []  # neither the result nor its part file


def test_the_run_command_can_keep_the_study_in_one_process():
    from femstudy.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["run", "case.toml"]).parallel is True
    assert parser.parse_args(["run", "case.toml", "--serial"]).parallel is False


def _lane_in_a_pool_worker(_):
    with Lanes() as lanes:
        lane = lanes.start("inner", lambda: 6 * 7)
        return lane.forked, lane.result()


@forking
def test_a_process_pool_worker_runs_its_lanes_itself():
    """A daemonic process may not have children: its lanes run in it."""
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.map(_lane_in_a_pool_worker, [0]) == [(False, 42)]


def test_a_block_can_be_entered_again():
    """One Lanes object serves one study after another (the command line's several cases)."""
    lanes = Lanes()
    for k in range(2):
        with lanes:
            assert lanes.start("answer", lambda: 40 + k).result() == 40 + k
        assert lanes._limits is None


@forking
def test_a_fork_that_fails_leaves_the_work_to_the_caller(monkeypatch):
    import multiprocessing.process

    def no_fork(self):
        raise OSError(12, "Cannot allocate memory")

    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", no_fork)
    with Lanes() as lanes:
        lane = lanes.start("unforkable", lambda: os.getpid())
        assert not lane.forked and lane.result() == os.getpid()


@forking
def test_a_child_leaves_the_consoles_progress_bars_to_its_parent():
    import io
    import threading

    from tqdm import tqdm

    from femstudy.console import ConsoleHandler

    stream = io.StringIO()
    handler = ConsoleHandler(stream=stream)
    handler.bars["transient steps"] = (tqdm(total=10, file=stream), threading.Event())
    with Lanes() as lanes:
        in_child = lanes.start("child", lambda: (dict(handler.bars), stream.getvalue()))
        bars, _ = in_child.result()
    assert bars == {} and "transient steps" in handler.bars  # dropped there, kept here
    handler._close_bars()


@pytest.mark.parametrize("parallel", [True, False])
def test_a_lane_started_before_its_input_warms_up_then_runs_on_what_it_is_given(parallel):
    """The child runs ``warm`` at once (here it records its pid in a module global, which the
    child then sees and the caller does not), then waits for give(); without forking, fn runs in
    the caller on result() and warm is skipped."""
    data = np.arange(2_000_000.0)  # 16 MB: more than a pipe holds, sent while the child may still warm
    with Lanes(parallel) as lanes:
        lane = lanes.start_given("weigh", lambda x: (os.getpid(), WARMED.get("pid"), float(x @ x)),
                                 warm=lambda: WARMED.update(pid=os.getpid()))
        lane.give(data)
        pid, warmed, value = lane.result()
    assert value == pytest.approx(float(data @ data))
    assert "pid" not in WARMED  # warm ran in the child only, if anywhere
    assert warmed == (pid if lane.forked else None) and (pid != os.getpid()) == lane.forked
    assert lane.seconds >= 0


WARMED: dict = {}


@forking
def test_a_lane_never_given_its_input_ends_with_the_block():
    with Lanes() as lanes:
        lane = lanes.start_given("waits", lambda x: x)
    assert lane.exitcode is not None  # ended and reaped, not left waiting


@forking
def test_an_error_while_warming_up_is_raised_in_the_caller():
    def no_library():
        raise ImportError("no module named 'pyvista'")

    with Lanes() as lanes:
        lane = lanes.start_given("picture", lambda x: x, warm=no_library)
        lane.give(np.zeros(3_000_000))  # the child has ended: the input goes nowhere, quietly
        with pytest.raises(ImportError, match="pyvista"):
            lane.result()
