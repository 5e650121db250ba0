"""Many fits (or other work) on one problem at once, spread over the cores this process may use.

The search (:mod:`.search`) fits every subset of the catalogue in every combination of its
members' candidates; the fits of one subset size depend only on the smaller ones, so each size's
fits are independent. Inside a :class:`FitPool` block they go to forked worker processes that
hold the problem from the fork (nothing large is sent), one fit per task so that a slow fit does
not hold up a share of the others. Each worker sends back the optimum (parameters, χ² per
channel, model, size); the caller's :class:`~.fit.Fit` evaluates the model at those parameters
again when its evaluation is first read. A fit is single-threaded and deterministic, so the fits,
and the diagnosis, are the same to the last digit as one by one in the caller — which is what
happens where forking is not safe (:func:`femstudy.lanes.can_fork`: not on Linux, one core,
inside a pool worker), for a single fit, with ``workers=1``, and (with a warning) when a worker
dies. Other independent work goes the same way through :meth:`FitPool.run`: the pulsation's
frequency scans (:mod:`.search`), and the verdict's scans for competing shapes, its refits with
them and its scans of each kind of shape (:mod:`.verdict`, :mod:`.outside`).
"""

from __future__ import annotations

import logging
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from functools import partial
from typing import Callable

from femstudy.diagnosis.fit import Fit, fit
from femstudy.diagnosis.model import Spec, evaluate, layout
from femstudy.diagnosis.problem import Problem
from femstudy.lanes import can_fork, cores

log = logging.getLogger(__name__)

#: The problem a worker works on (given at its fork, never pickled).
_PROBLEM: Problem | None = None


def _hold(problem: Problem) -> None:
    global _PROBLEM
    _PROBLEM = problem


def _apply(task: tuple[Callable, object]):
    fn, item = task
    return fn(_PROBLEM, item)


def portable(f: Fit) -> tuple:
    """What a worker sends back of a fit, or is sent of one: (spec, parameters, χ², model, size)."""
    return f.spec, f.theta, f.chi2, f.model, f.n_params


def restored(problem: Problem, sent: tuple) -> Fit:
    """The fit of :func:`portable`'s tuple, its evaluation rebuilt when first read."""
    spec, theta, chi2, model, n_params = sent
    lay = layout(problem, spec)
    return Fit(spec, lay, theta, chi2, model, n_params, partial(evaluate, problem, spec, lay, theta))


def _optimum(problem: Problem, task: tuple[Spec, dict]) -> tuple:
    spec, start = task
    return portable(fit(problem, spec, start))


class FitPool:
    """``with FitPool(problem) as pool: fits = pool.fit_many([(spec, start), ...])``: the fits
    in the order of the tasks, as :func:`.fit.fit` would give them one by one; ``pool.run(fn,
    items)``: ``fn(problem, item)`` for each item, in order."""

    def __init__(self, problem: Problem, workers: int | None = None):
        self.problem = problem
        self.workers = cores() if workers is None else workers
        self._executor: ProcessPoolExecutor | None = None

    def __enter__(self) -> "FitPool":
        if self.workers > 1 and can_fork():
            self._executor = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("fork"),
                                                 initializer=_hold, initargs=(self.problem,))
        return self

    def __exit__(self, *exc) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None

    @property
    def forked(self) -> bool:
        """Whether the work goes to worker processes (inside the block)."""
        return self._executor is not None

    def run(self, fn: Callable, items: list) -> list:
        """``fn(problem, item)`` for each item, in order; ``fn`` is sent by its name (a function
        defined at a module's top level) and its results come back pickled."""
        if self._executor is None or len(items) < 2:
            return [fn(self.problem, item) for item in items]
        try:
            return list(self._executor.map(_apply, [(fn, item) for item in items]))
        except (BrokenProcessPool, OSError) as exc:   # a worker killed, or no process left to fork
            log.warning("working in this process only: a worker process failed (%s)", exc)
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
            return self.run(fn, items)

    def fit_many(self, tasks: list[tuple[Spec, dict]]) -> list[Fit]:
        """Each (spec, start) fitted (:func:`.fit.fit` with that start)."""
        if self._executor is None or len(tasks) < 2:
            return [fit(self.problem, spec, start) for spec, start in tasks]
        return [restored(self.problem, sent) for sent in self.run(_optimum, tasks)]
