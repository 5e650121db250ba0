"""Executors: how a study runs its independent parts (hole models, results files).

A study hands each part to an executor as ``executor.start(name, fn)`` and later asks the
returned handle for ``result()``; it enters the executor (``with executor:``) around that. A
part whose input is computed later is started as ``executor.start_given(name, fn, warm)`` and
handed it by ``give(x)``: a forking executor readies its process meanwhile (``warm()``). The
default, :class:`InProcess`, runs a part in the caller when its result is asked for, so the
pipeline needs nothing else. The command line chooses :class:`femstudy.lanes.Lanes` instead,
which runs parts in forked processes beside the caller; sweeps run their points on process
pools or Dask (:mod:`femstudy.sweeps.execute`). Any object with the same four methods will do.
"""

from __future__ import annotations

import time
from functools import partial
from typing import Any, Callable, Protocol


class Handle(Protocol):
    """A part started by an executor: its value, its wall time [s] and whether another process ran it."""

    seconds: float
    forked: bool

    def result(self) -> Any: ...


class Given(Handle, Protocol):
    """A part started before its input exists: :meth:`give` hands it the input."""

    def give(self, value: Any) -> None: ...


class Executor(Protocol):
    """Runs parts of a study: entered around them, :meth:`start` returns a :class:`Handle`."""

    def __enter__(self) -> "Executor": ...

    def __exit__(self, *exc) -> None: ...

    def start(self, name: str, fn: Callable[[], Any]) -> Handle: ...

    def start_given(self, name: str, fn: Callable[[Any], Any], warm: Callable[[], Any] | None = None) -> Given: ...


class Deferred:
    """A part run in this process on the first :meth:`result` call (``fn(x)`` once
    :meth:`give` has handed it x, for a part started by ``start_given``)."""

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

    def give(self, value: Any) -> None:
        self._fn = partial(self._fn, value)


class InProcess:
    """The default executor: every part runs in the caller, when its result is asked for.

    Examples
    --------
    >>> with InProcess() as executor:
    ...     part = executor.start("answer", lambda: 6 * 7)
    ...     part.result(), part.forked
    (42, False)
    >>> with InProcess() as executor:
    ...     later = executor.start_given("double", lambda x: 2 * x)
    ...     later.give(21)
    ...     later.result()
    42
    """

    forking = False

    def __enter__(self) -> "InProcess":
        return self

    def __exit__(self, *exc) -> None:
        return None

    def start(self, name: str, fn: Callable[[], Any]) -> Deferred:
        return Deferred(name, fn)

    def start_given(self, name: str, fn: Callable[[Any], Any], warm: Callable[[], Any] | None = None) -> Deferred:
        """``fn(x)`` run here on :meth:`Deferred.result`, x handed by :meth:`Deferred.give`
        (``warm`` readies a process of its own; here there is none)."""
        return Deferred(name, fn)
