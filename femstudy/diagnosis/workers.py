"""Independent subset fits on several processes.

The fits of one size level of the subsets, the drop-one polishes, the held-out folds and the
shapes competing with a mechanism do not depend on each other. A *fitter* takes a list of
requests ``(problem, subset, starts, options)`` and returns, per request, what
``fit_subset(problem, subset, starts, **options)`` returns. :func:`fitter` gives the serial
one (:func:`~femstudy.diagnosis.fit.fit_each`) for ``workers=1``, otherwise one backed by a
process pool that runs every start of every request as its own task and keeps, per request,
the start with the lowest χ²: the result ``fit_subset`` gives with all the starts.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

from threadpoolctl import threadpool_limits

from femstudy.diagnosis.fit import Fit, fit_each, fit_subset

def _one_start(task) -> Fit:
    problem, subset, start, options = task
    return fit_subset(problem, subset, [] if start is None else [start], **options)


def _single_threaded() -> None:
    threadpool_limits(1)


class PoolFitter:
    """A fitter on a process pool: one task per start (see the module)."""

    def __init__(self, executor: ProcessPoolExecutor):
        self.executor = executor

    def __call__(self, requests: list) -> list[Fit]:
        owners, tasks = [], []
        for i, (problem, subset, starts, options) in enumerate(requests):
            for start in starts or [None]:
                owners.append(i)
                tasks.append((problem, subset, start, options))
        best: dict[int, Fit] = {}
        for i, fit in zip(owners, self.executor.map(_one_start, tasks)):
            if i not in best or fit.chi2_total < best[i].chi2_total:
                best[i] = fit
        return [best[i] for i in range(len(requests))]


@contextmanager
def fitter(workers: int = 1):
    """The fitter for ``workers`` processes (serial for 1, or where processes cannot be forked).

    Examples
    --------
    >>> with fitter(2) as fits_of:                                   # doctest: +SKIP
    ...     fit, = fits_of([(problem, frozenset(), [start], {})])
    """
    if workers <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        yield fit_each
        return
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                             initializer=_single_threaded) as executor:
        yield PoolFitter(executor)
