"""Lanes of work: functions run in forked processes while the caller goes on.

Most of a study after its global solves is single-threaded Python and NumPy (the hole models,
the modal and resolved analyses, the figures and field files), so on a machine with two or
more cores the study runs such parts side by side. Inside a :class:`Lanes` block,
:meth:`Lanes.start` forks a child that runs a function and sends its result back pickled;
every process of the block (the caller and its children) uses half of the cores' BLAS/MKL
threads, at least one (threadpoolctl). Without ``fork`` on Linux (Windows, macOS), with one
core, or with ``parallel=False``, a function runs in the caller when its result is asked
for: the results are the same either way.

An exception raised in a child is raised again in the caller, with the child's traceback as
its cause; a :class:`~femstudy.errors.UserError` keeps its one-line message. Leaving the block
ends every child still running, and a child ends when its parent does (killed, say), so no
lane outlives the run that started it.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import time
import traceback
from typing import Callable


def cores() -> int:
    """The cores this process may run on (its CPU affinity)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def can_fork() -> bool:
    """Whether lanes fork here: Linux (fork is safe with the BLAS/MKL runtimes used) and ≥ 2 cores."""
    return sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods() and cores() >= 2


class ChildTraceback(Exception):
    """The traceback of an exception raised in a lane's child process (set as its cause)."""


class Lane:
    """One function's result, computed in a child process or, failing that, on demand.

    seconds : the function's wall time [s] once the result is in (NaN before)
    forked : whether a child computes it
    """

    def __init__(self, name: str, fn: Callable, threads: int | None):
        self.name, self._fn, self._value, self._done = name, fn, None, False
        self.seconds = float("nan")
        self._process = self._receive = None
        if threads is not None:
            context = multiprocessing.get_context("fork")
            self._receive, send = context.Pipe(duplex=False)
            self._process = context.Process(target=_child, args=(fn, send, threads, os.getpid()), name=f"femstudy {name}",
                                            daemon=True)
            self._process.start()
            send.close()  # the child holds the only sending end: its exit ends the pipe

    @property
    def forked(self) -> bool:
        return self._process is not None

    def result(self):
        """The function's return value (waits for the child); its exception, raised again here."""
        if not self._done:
            self._value, self.seconds = self._run() if self._process is None else self._receive_result()
            self._done = True
        return self._value

    def _run(self):
        start = time.perf_counter()
        return self._fn(), time.perf_counter() - start

    def _receive_result(self):
        try:
            status, value, seconds, text = self._receive.recv()
        except EOFError:
            self._process.join()
            raise RuntimeError(f"the {self.name} process ended without a result "
                               f"(exit code {self._process.exitcode})") from None
        finally:
            self._receive.close()
        self._process.join()
        if status == "error":
            raise value from ChildTraceback(text)
        return value, seconds

    def close(self) -> None:
        """End the child if it still runs (the caller failed or gave up on the result)."""
        if self._process is not None and self._process.is_alive():
            self._process.terminate()
            self._process.join()


class Lanes:
    """A block whose :meth:`start` runs functions beside the caller (see the module).

    Example
    -------
    >>> with Lanes() as lanes:
    ...     there = lanes.start("answer", lambda: 6 * 7)
    ...     here = sum(range(10))
    ...     here, there.result()
    (45, 42)
    """

    def __init__(self, parallel: bool = True):
        self.forking = parallel and can_fork()
        self.threads = max(1, cores() // 2)
        self._lanes: list[Lane] = []
        self._limits = None

    def __enter__(self) -> "Lanes":
        if self.forking:
            from threadpoolctl import threadpool_limits

            self._limits = threadpool_limits(limits=self.threads)
        return self

    def start(self, name: str, fn: Callable) -> Lane:
        """Run ``fn()`` in a forked child now, or on :meth:`Lane.result` when lanes do not fork."""
        lane = Lane(name, fn, self.threads if self.forking else None)
        self._lanes.append(lane)
        return lane

    def __exit__(self, *exc) -> None:
        for lane in self._lanes:
            lane.close()
        if self._limits is not None:
            self._limits.restore_original_limits()


def _child(fn: Callable, send, threads: int, parent: int) -> None:
    """A child's whole life: limit its threads, run ``fn``, send (status, value, seconds, traceback)."""
    from threadpoolctl import threadpool_limits

    start = time.perf_counter()
    _end_with_parent(parent)
    try:
        threadpool_limits(limits=threads)
        message = ("ok", fn(), time.perf_counter() - start, "")
    except BaseException as exc:  # everything goes back to the caller, which decides
        message = ("error", exc, time.perf_counter() - start, traceback.format_exc())
    try:
        send.send(message)
    except OSError:  # the parent is gone
        pass
    except Exception as exc:  # the value or the exception cannot be pickled
        send.send(("error", RuntimeError(f"the result could not be sent back: {exc}"), message[2], message[3]))
    send.close()


def _end_with_parent(parent: int) -> None:
    """Have the kernel send this process SIGTERM when its parent (pid ``parent``) ends (Linux
    prctl PR_SET_PDEATHSIG), and end now if it already has."""
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG
    if os.getppid() != parent:
        os._exit(1)
