"""Executors: how a study runs its independent parts (hole models, results files).

A study hands each part to an executor as ``executor.start(name, fn)`` and later asks the
returned handle for ``result()``; it enters the executor (``with executor:``) around that. The
default, :class:`InProcess`, runs a part in the caller when its result is asked for, so the
pipeline needs nothing else. The command line chooses :class:`femstudy.lanes.Lanes` instead,
which runs parts in forked processes beside the caller; sweeps run their points on process
pools or Dask (:mod:`femstudy.sweeps.execute`). Any object with the same three methods will do.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Protocol


class Handle(Protocol):
    """A part started by an executor: its value, its wall time [s] and whether another process ran it."""

    seconds: float
    forked: bool

    def result(self) -> Any: ...


class Executor(Protocol):
    """Runs parts of a study: entered around them, :meth:`start` returns a :class:`Handle`."""

    def __enter__(self) -> "Executor": ...

    def __exit__(self, *exc) -> None: ...

    def start(self, name: str, fn: Callable[[], Any]) -> Handle: ...


class Deferred:
    """A part run in this process on the first :meth:`result` call."""

    forked = False

    def __init__(self, name: str, fn: Callable[[], Any]):
        self.name, self._fn, self._done, self._value = name, fn, False, None
        self.seconds = float("nan")

    def result(self) -> Any:
        if not self._done:
            start = time.perf_counter()
            self._value = self._fn()
            self.seconds, self._done = time.perf_counter() - start, True
        return self._value


class InProcess:
    """The default executor: every part runs in the caller, when its result is asked for.

    Examples
    --------
    >>> with InProcess() as executor:
    ...     part = executor.start("answer", lambda: 6 * 7)
    ...     part.result(), part.forked
    (42, False)
    """

    forking = False

    def __enter__(self) -> "InProcess":
        return self

    def __exit__(self, *exc) -> None:
        return None

    def start(self, name: str, fn: Callable[[], Any]) -> Deferred:
        return Deferred(name, fn)
