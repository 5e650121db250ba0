"""Run independent sweep points locally (process pool) or on a Dask cluster, resumably.

Every finished point is written at once and atomically as ``points/<id>.json``; a sweep
started again skips the points whose file exists and matches, so a sweep killed part-way
loses only the points that were running. Locally, points are admitted only while their
estimated memory fits the machine (so two near-1M-DOF factorisations never run at once on
24 GB), and the BLAS/MKL threads are split between the workers (threadpoolctl, set in each
worker process when it starts).
"""

from __future__ import annotations

import json
import logging
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable

from femstudy import atomic
from femstudy.errors import UserError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Point:
    """One independent computation: a kind ("mesh" or "study") and case-file overrides."""

    kind: str
    overrides: dict[str, Any] = field(hash=False)
    label: str = ""

    @property
    def id(self) -> str:
        """Stable file-name-safe identity of the point."""
        import hashlib

        text = json.dumps({"kind": self.kind, "overrides": self.overrides}, sort_keys=True)
        return f"{self.kind}-{hashlib.sha256(text.encode()).hexdigest()[:12]}"


def _load_finished(folder: Path, points: list[Point]) -> dict[str, dict]:
    finished = {}
    for point in points:
        path = folder / f"{point.id}.json"
        if not path.is_file():
            continue
        try:
            record = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            continue  # unreadable: recompute it
        if record.get("point", {}).get("overrides") == point.overrides:
            finished[point.id] = record
    return finished


def _record(point: Point, result: dict) -> dict:
    return {"point": {"id": point.id, "kind": point.kind, "label": point.label, "overrides": point.overrides},
            "result": result}


def _store(folder: Path, point: Point, result: dict) -> dict:
    record = _record(point, result)
    atomic.write_text(folder / f"{point.id}.json", json.dumps(record, indent=1, default=float))
    return record


def execute(points: list[Point], folder: Path, evaluate: Callable, args: tuple = (), *, workers: int = 1,
            scheduler: str | None = None, memory_bytes: Callable | None = None,
            memory_budget_bytes: float | None = None, label: str = "sweep points") -> list[dict]:
    """Evaluate ``evaluate(point, *args) -> dict`` for every point not finished in ``folder``.

    Returns the records of all points, in the order given. ``memory_bytes(point)`` estimates
    a point's peak memory for local admission control; ``label`` names the progress bar.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    finished = _load_finished(folder, points)
    todo = [p for p in points if p.id not in finished]
    log.info("%d of %d points already finished; computing %d%s", len(finished), len(points), len(todo),
             f" on {scheduler}" if scheduler else f" with {workers} worker{'s' * (workers > 1)}")
    if todo:
        if scheduler:
            _run_dask(todo, folder, evaluate, args, scheduler, finished, label)
        elif workers <= 1:
            for k, point in enumerate(todo, 1):
                finished[point.id] = _store(folder, point, evaluate(point, *args))
                _done(point, len(finished), len(points), label)
        else:
            _run_pool(todo, folder, evaluate, args, workers, memory_bytes, memory_budget_bytes, finished,
                      len(points), label)
    return [finished[p.id] for p in points]


def _done(point: Point, finished: int, total: int, label: str = "sweep points") -> None:
    log.info("point done (%d of %d finished): %s", finished, total, point.label,
             extra={"progress": (label, finished, total)})


def _limit_threads(threads: int) -> None:
    """Worker start-up: load the linear-algebra runtimes, then limit their threads."""
    from threadpoolctl import threadpool_limits

    from femstudy.fe.linsolve import load_runtimes

    load_runtimes()
    threadpool_limits(limits=threads)


def _run_pool(todo, folder, evaluate, args, workers, memory_bytes, budget, finished, total, label) -> None:
    import psutil

    budget = budget or 0.8 * psutil.virtual_memory().available
    need = {p.id: (memory_bytes(p) if memory_bytes else 0.0) for p in todo}
    for point in todo:
        if need[point.id] > budget:
            log.warning("point %s may need %.1f GB, more than the %.1f GB available; it will run alone",
                        point.label, need[point.id] / 1e9, budget / 1e9)
    queue = sorted(todo, key=lambda p: -need[p.id])
    threads = max(1, (os.cpu_count() or 1) // workers)
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"), initializer=_limit_threads,
                             initargs=(threads,)) as pool:
        running: dict = {}
        while queue or running:
            in_use = sum(need[p.id] for p in running.values())
            for point in list(queue):
                if len(running) >= workers:
                    break
                if not running or in_use + need[point.id] <= budget:
                    running[pool.submit(evaluate, point, *args)] = point
                    in_use += need[point.id]
                    queue.remove(point)
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                point = running.pop(future)
                finished[point.id] = _store(folder, point, _result(future, point))
                _done(point, len(finished), total, label)


def _result(future, point: Point) -> dict:
    try:
        return future.result()
    except UserError as exc:
        raise UserError(f"sweep point {point.label}: {exc}") from None


def _run_dask(todo, folder, evaluate, args, scheduler, finished, label="sweep points") -> None:
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise UserError("--scheduler needs dask.distributed: pip install 'femstudy[cluster]'") from None
    try:
        client = Client(scheduler, timeout="20s")
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise UserError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
    total = len(finished) + len(todo)
    with client:
        futures = {client.submit(evaluate, point, *args, pure=False, key=f"femstudy-{point.id}"): point
                   for point in todo}
        for future in as_completed(futures):
            point = futures[future]
            finished[point.id] = _store(folder, point, _result(future, point))
            _done(point, len(finished), total, label)
