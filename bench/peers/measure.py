"""Whole-process wall time and peak memory of a command, measured from outside.

Wall time runs from just before the fork to the child's exit. Peak memory is the child's
``ru_maxrss`` from ``wait4``: the kernel's high-water mark of resident memory of the child
or of the largest of its descendants it waited for, in MB = 2^20 bytes. A run that forks
(a study's lanes, femstudy.lanes) is several processes at once, whose resident sets share
the pages they were forked with; ``tree_peak_MB`` is the largest sum of their proportional
set sizes (PSS: each shared page counted once over the processes sharing it), sampled every
:data:`SAMPLE_S` seconds, so the memory the whole run occupies, to within a short peak.
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
SAMPLE_S = 0.05


@dataclass(frozen=True)
class Measurement:
    """One run: ``wall_s`` [s], ``peak_MB`` [MiB] (largest process), ``tree_peak_MB`` [MiB]
    (all its processes, sampled), exit status and where its output went."""

    command: tuple[str, ...]
    wall_s: float
    peak_MB: float
    returncode: int
    log: Path
    tree_peak_MB: float = float("nan")

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
    return Measurement(tuple(command), wall, usage.ru_maxrss / 1024, proc.returncode, log,
                       tree_peak[0] / 2 ** 20 or float("nan"))


def _sample_tree(pid: int, done: threading.Event, peak: list) -> None:
    """Raise ``peak[0]`` to the summed PSS [bytes] of ``pid`` and its descendants until ``done``."""
    import psutil

    while not done.wait(SAMPLE_S):
        try:
            root = psutil.Process(pid)
            processes = [root] + root.children(recursive=True)
        except psutil.Error:
            continue
        total = 0
        for p in processes:
            try:
                total += p.memory_full_info().pss
            except psutil.Error:  # it ended meanwhile
                pass
        peak[0] = max(peak[0], total)
