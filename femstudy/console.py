"""Console messages: results on stdout, progress and warnings on stderr."""

from __future__ import annotations

import sys
import time


class Console:
    """Phase messages with elapsed wall time; ``quiet`` silences progress, not warnings."""

    def __init__(self, quiet: bool = False) -> None:
        self.quiet = quiet
        self.start = time.perf_counter()

    def progress(self, message: str) -> None:
        """A progress line ``[  12.3 s] message`` on stderr, unless quiet."""
        if not self.quiet:
            print(f"[{time.perf_counter() - self.start:7.1f} s] {message}", file=sys.stderr, flush=True)

    @staticmethod
    def warn(message: str) -> None:
        """A ``femstudy: warning: ...`` line on stderr, always shown."""
        print(f"femstudy: warning: {message}", file=sys.stderr, flush=True)
