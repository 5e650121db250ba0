"""Whole-process wall time and peak memory of a command, measured from outside.

Wall time runs from just before the fork to the child's exit. Peak memory is the child's
``ru_maxrss`` from ``wait4``: the kernel's high-water mark of resident memory of the child
or of the largest of its descendants it waited for (every run here is a single process,
with threads), in MB = 2^20 bytes.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Measurement:
    """One run: ``wall_s`` [s], ``peak_MB`` [MiB], exit status and where its output went."""

    command: tuple[str, ...]
    wall_s: float
    peak_MB: float
    returncode: int
    log: Path

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
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            if timer:
                timer.cancel()
        wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    return Measurement(tuple(command), wall, usage.ru_maxrss / 1024, proc.returncode, log)
