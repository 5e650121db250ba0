"""Whole-process wall time and peak memory of a command, measured from outside.

Wall time runs from just before the fork to the child's exit. Peak memory is the child's
``ru_maxrss`` from ``wait4``: the kernel's high-water mark of resident memory of the child
or of the largest of its descendants it waited for, in MB = 2^20 bytes. A run that forks
(a study's lanes, femstudy.lanes) is several processes at once, whose resident sets share
the pages they were forked with; ``tree_peak_MB`` is the larger of ``peak_MB`` and the
largest sum of their proportional set sizes (PSS: each shared page counted once over the
processes sharing it) sampled every :data:`SAMPLE_S` seconds while there are several: the
memory the whole run occupies, to within a peak shorter than a sample.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path

#: Interval [s] between samples of the process tree's memory.
SAMPLE_S = 0.5


@dataclass(frozen=True)
class Measurement:
    """One run: ``wall_s`` [s], ``peak_MB`` [MiB] (largest process), ``tree_peak_MB`` [MiB]
    (all its processes, sampled), exit status, where its output went, and ``cpu_s`` [s] (user +
    system of the child and the descendants it waited for)."""

    command: tuple[str, ...]
    wall_s: float
    peak_MB: float
    returncode: int
    log: Path
    tree_peak_MB: float = float("nan")
    cpu_s: float = float("nan")

    def check(self) -> "Measurement":
        if self.returncode != 0:
            tail = self.log.read_text(errors="replace")[-1500:] if self.log.exists() else ""
            raise RuntimeError(f"{shlex.join(self.command)} failed with status {self.returncode}:\n{tail}")
        return self


def measure(command: list[str], log: str | os.PathLike, cwd: str | os.PathLike | None = None,
            env: dict[str, str] | None = None, timeout_s: float | None = None) -> Measurement:
    """Run ``command`` with stdout and stderr going to ``log``; kill it after ``timeout_s``."""
    log = Path(log)
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "wb") as out:
        start = time.perf_counter()
        proc = subprocess.Popen(command, cwd=cwd, env=env, stdout=out, stderr=subprocess.STDOUT)
        timer = threading.Timer(timeout_s, proc.kill) if timeout_s else None
        if timer:
            timer.start()
        done, tree_peak = threading.Event(), [0.0]
        sampler = threading.Thread(target=_sample_tree, args=(proc.pid, done, tree_peak), daemon=True)
        sampler.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            done.set()
            if timer:
                timer.cancel()
        wall = time.perf_counter() - start
        sampler.join()
    proc.returncode = os.waitstatus_to_exitcode(status)
    peak = usage.ru_maxrss / 1024
    return Measurement(tuple(command), wall, peak, proc.returncode, log, max(peak, tree_peak[0] / 2 ** 20),
                       usage.ru_utime + usage.ru_stime)


def _sample_tree(pid: int, done: threading.Event, peak: list) -> None:
    """Raise ``peak[0]`` to the summed PSS [bytes] of ``pid`` and its descendants, sampled
    while it has any, until ``done``. Reading a process's PSS walks its page tables (~10 ms
    for a study's 1.5 GB): it is read only then, and seldom (the samples of a default study's
    lanes cost ~0.2 s of CPU); a single process's peak is its ru_maxrss."""
    while not done.wait(SAMPLE_S):
        processes = _tree(pid)
        if len(processes) < 2:
            continue
        total = 0
        for p in processes:
            try:
                with open(f"/proc/{p}/smaps_rollup") as rollup:
                    total += next(int(line.split()[1]) for line in rollup if line.startswith("Pss:")) * 1024
            except (OSError, StopIteration, ValueError):  # it ended meanwhile
                pass
        peak[0] = max(peak[0], total)


def _tree(pid: int) -> list[int]:
    """``pid`` and its descendants (from /proc/<pid>/task/*/children)."""
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        found.append(p)
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as children:
                    todo += [int(c) for c in children.read().split()]
        except OSError:  # it ended meanwhile
            pass
    return found
