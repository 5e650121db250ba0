"""Lanes of work: functions run in forked processes while the caller goes on (an executor,
:mod:`femstudy.execution`, that the command line gives a study).

Most of a study after its global solves is single-threaded Python and NumPy (the hole models,
the modal and resolved analyses, the figures and field files), so on a machine with two or
more cores the study runs such parts side by side. Inside a :class:`Lanes` block,
:meth:`Lanes.start` forks a child that runs a function and sends its result back pickled;
every process of the block (the caller and its children) uses half of the cores' BLAS/MKL
threads, at least one (threadpoolctl). A function runs in the caller instead, when its result
is asked for, wherever forking is not safe (:func:`can_fork`) or with ``parallel=False``; its
result is then the same to round-off (the thread counts, and so the order of BLAS sums, differ).

An exception raised in a child is raised again in the caller, with the child's traceback as
its cause; a :class:`~femstudy.errors.UserError` keeps its one-line message, and so does a
failure of the machine (no memory, a full disk: an ``OSError`` or ``MemoryError`` travels back
as itself). A child that dies without a result (killed, or aborted in C code) is a
:class:`LaneFailed` naming the lane and the signal; the command line turns each into one line
(:mod:`femstudy.cli`). Leaving the block
ends every child still running (SIGTERM, on which a child unwinds, so its atomic writes clean
up), and a child ends when its parent does (killed, say): no lane outlives its run. Ctrl-C
stops the caller, whose block then ends the children. A child's log records go to the
handlers it inherited (the console), not to ones attached to the caller later.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
import traceback
from functools import partial
from typing import Callable


def cores() -> int:
    """The cores this process may run on (its CPU affinity)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def can_fork() -> bool:
    """Whether lanes fork here: on Linux with ≥ 2 cores, and not from a daemonic process (a
    process-pool worker may not have children). A process with an open render window (a
    notebook's pyvista plot) should not fork: give its study the default executor instead."""
    return (sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()
            and cores() >= 2 and not multiprocessing.current_process().daemon)


class ChildTraceback(Exception):
    """The traceback of an exception raised in a lane's child process (set as its cause)."""


class LaneFailed(RuntimeError):
    """A lane's child process ended without sending a result (killed, or aborted in C code).
    ``environment``: it was killed in a way the machine explains (out of memory, file size)."""

    def __init__(self, message: str, environment: bool = False):
        super().__init__(message)
        self.environment = environment


def describe_exit(code: int | None) -> str:
    """A child's exit status in words: "exit code 3", "killed by SIGKILL"."""
    if code is None:
        return "no exit status"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


class Lane:
    """One function's result, computed in a child process or, failing that, on demand.

    seconds : the function's wall time [s] once the result is in (NaN before; for a lane
              given its input, from when the input arrived)
    forked : whether a child computes it
    exitcode : the child's exit status once it ended (negative: the signal that ended it)

    ``given``: the function takes one argument, sent later by :meth:`give`; ``warm`` (forked
    lanes only) runs in the child before it waits for it.
    """

    def __init__(self, name: str, fn: Callable, threads: int | None, given: bool = False,
                 warm: Callable[[], object] | None = None):
        self.name, self._fn, self._value, self._done = name, fn, None, False
        self.seconds = float("nan")
        self.exitcode = None
        self._process = self._receive = self._input = self._sender = None
        if threads is not None:
            context = multiprocessing.get_context("fork")
            receive, send = context.Pipe(duplex=False)
            take, give = context.Pipe(duplex=False) if given else (None, None)
            process = context.Process(target=_child, args=(fn, send, threads, os.getpid(), take, warm),
                                      name=f"femstudy {name}", daemon=True)
            try:
                process.start()
            except OSError:  # no memory or process left to fork: the caller runs it
                receive.close()
                if give is not None:
                    give.close()
                return
            finally:
                send.close()  # the child holds the only sending end: its exit ends the pipe
                if take is not None:
                    take.close()
            self._process, self._receive, self._input = process, receive, give

    def give(self, value) -> None:
        """The input of a lane started by :meth:`Lanes.start_given`: sent to its child from a
        thread (the child may still be warming up), or kept for the caller to run with."""
        if self._input is None:
            self._fn = partial(self._fn, value)
            return
        self._sender = threading.Thread(target=_send_quietly, args=(self._input, value),
                                        name=f"femstudy {self.name} input", daemon=True)
        self._sender.start()

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
            self.close()
            hint = ("; the machine may have run out of memory" if self.exitcode == -signal.SIGKILL else
                    "; is the disk full, or a file size limit set?" if self.exitcode in (-signal.SIGXFSZ, -signal.SIGBUS)
                    else "")
            raise LaneFailed(f"the {self.name} process ended without a result ({describe_exit(self.exitcode)})"
                             f"{hint}", environment=bool(hint)) from None
        self.close()
        if status == "error":
            raise value from ChildTraceback(text)
        return value, seconds

    def close(self) -> None:
        """End the child if it still runs, wait for it and release its pipes and handles."""
        if self._process is None or self.exitcode is not None:
            return
        try:
            if self._process.is_alive():
                self._process.terminate()
            self._process.join()
            self.exitcode = self._process.exitcode
        finally:
            self._receive.close()
            if self._sender is not None:
                self._sender.join()  # the child has ended: its input pipe no longer blocks
            if self._input is not None:
                self._input.close()
            with contextlib.suppress(ValueError):  # still running after a second interrupt
                self._process.close()


class Lanes:
    """A block whose :meth:`start` runs functions beside the caller (see the module).

    Examples
    --------
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
        self._lanes = []  # a block may be entered again (one study after another)
        if self.forking:
            from threadpoolctl import threadpool_limits

            self._limits = threadpool_limits(limits=self.threads)
        return self

    def start(self, name: str, fn: Callable) -> Lane:
        """Run ``fn()`` in a forked child now, or on :meth:`Lane.result` when lanes do not fork."""
        lane = Lane(name, fn, self.threads if self.forking else None)
        self._lanes.append(lane)
        return lane

    def start_given(self, name: str, fn: Callable, warm: Callable[[], object] | None = None) -> Lane:
        """Fork a child now that runs ``warm()`` and then ``fn(x)`` once :meth:`Lane.give` sends x;
        when lanes do not fork, ``fn(x)`` runs on :meth:`Lane.result` (``warm`` is skipped: it
        only readies a child)."""
        lane = Lane(name, fn, self.threads if self.forking else None, given=True, warm=warm)
        self._lanes.append(lane)
        return lane

    def __exit__(self, *exc) -> None:
        with contextlib.ExitStack() as stack:  # every lane closed and the limits restored, whatever fails
            if self._limits is not None:
                stack.callback(self._limits.restore_original_limits)
            for lane in self._lanes:
                stack.callback(lane.close)
        self._limits = None


def _send_quietly(connection, value) -> None:
    """Send ``value`` down ``connection``; a child that has ended (after an error of its own,
    which its result pipe carries) no longer reads it."""
    with contextlib.suppress(OSError):
        connection.send(value)


def _child(fn: Callable, send, threads: int, parent: int, given=None, warm: Callable[[], object] | None = None) -> None:
    """A child's whole life: signals set up, threads limited, ``warm`` run and the input
    awaited (a lane given its input later), ``fn`` run, (status, value, seconds, traceback) sent."""
    from threadpoolctl import threadpool_limits

    start = time.perf_counter()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the caller's to handle; it ends the lanes
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))  # unwind: atomic writes clean up
    _end_with_parent(parent)
    try:
        threadpool_limits(limits=threads)
        if given is not None:
            if warm is not None:
                warm()
            try:
                fn = partial(fn, given.recv())
            except EOFError:  # the caller closed the lane without giving its input: nothing to do
                return
            start = time.perf_counter()
        message = ("ok", fn(), time.perf_counter() - start, "")
    except SystemExit:  # terminated: the caller no longer waits for a result
        raise
    except BaseException as exc:  # everything else goes back to the caller, which decides
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
