"""What the command line shows of the library's log: results on stdout (printed by the
commands), progress and warnings on stderr.

The library reports through :mod:`logging` (logger ``femstudy``). A record may carry
``extra={"progress": (task, done, total)}`` (total None for a task of unknown length, done
None when it ends); on a terminal such records drive a progress bar per task, elsewhere they
are plain lines. Other INFO records are lines ``[  12.3 s] message``; warnings are
``femstudy: warning: message`` and are shown even with ``--quiet``.
"""

from __future__ import annotations

import logging
import os
import sys
import threading
import time
import weakref


class ConsoleHandler(logging.Handler):
    """Progress lines or bars and warnings on a stream (stderr)."""

    def __init__(self, quiet: bool = False, stream=None) -> None:
        super().__init__(logging.INFO)
        self.quiet = quiet
        self._stream = stream
        self.start = time.perf_counter()
        self.bars: dict = {}
        handler = weakref.ref(self)
        os.register_at_fork(after_in_child=lambda: (h := handler()) is not None and h._forget_bars())

    @property
    def stream(self):
        """The given stream, else whatever ``sys.stderr`` is now (it may be replaced, e.g. captured)."""
        return self._stream or sys.stderr

    @property
    def terminal(self) -> bool:
        return hasattr(self.stream, "isatty") and self.stream.isatty()

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        if record.levelno >= logging.WARNING:
            self._close_bars()
            print(f"femstudy: warning: {message}", file=self.stream, flush=True)
            return
        if self.quiet:
            return
        progress = getattr(record, "progress", None)
        if progress is not None and self.terminal:
            self._bar(*progress, message)
            return
        self._close_bars()
        print(f"[{time.perf_counter() - self.start:7.1f} s] {message}", file=self.stream, flush=True)

    def _bar(self, task: str, done, total, message: str) -> None:
        from tqdm import tqdm

        if done is None:  # the task ended
            entry = self.bars.pop(task, None)
            if entry is not None:
                entry[1].set()
                entry[0].close()
            return
        if task not in self.bars:
            bar = tqdm(total=total, desc=task, file=self.stream, leave=False, dynamic_ncols=True)
            stop = threading.Event()
            if total is None:  # a blocking task of unknown length: keep its clock moving
                threading.Thread(target=_tick, args=(bar, stop), daemon=True).start()
            self.bars[task] = (bar, stop)
        bar = self.bars[task][0]
        bar.n = done
        bar.set_postfix_str(message, refresh=True)

    def _forget_bars(self) -> None:
        """In a forked child (femstudy.lanes): the bars on the terminal are the parent's; drop
        them without drawing, so the child's lines neither close nor redraw them."""
        for bar, _ in self.bars.values():
            bar.disable = True
        self.bars = {}

    def _close_bars(self) -> None:
        for task in list(self.bars):
            self._bar(task, None, None, "")


def _tick(bar, stop: threading.Event) -> None:
    while not stop.wait(0.5):
        bar.refresh()


def install(quiet: bool = False) -> ConsoleHandler:
    """Route the ``femstudy`` logger to a fresh :class:`ConsoleHandler` (replacing earlier ones)."""
    logger = logging.getLogger("femstudy")
    for old in [h for h in logger.handlers if isinstance(h, ConsoleHandler)]:
        old._close_bars()
        logger.removeHandler(old)
    handler = ConsoleHandler(quiet)
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
    return handler
