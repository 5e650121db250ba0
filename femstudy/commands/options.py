"""Numbers on the command line: finite, and inside the range their quantity allows.

``type=number(0, 50, "mm/s")`` makes argparse refuse ``nan``, ``inf``, ``1e308`` or ``-2`` for
a feed with one line and exit status 2, before any work starts. The ranges are those of the
case-file schema (:mod:`femstudy.casefile`) where the quantity is one of its keys, and
otherwise what the quantity can physically be on a femur (docs/checks.md).
"""

from __future__ import annotations

import argparse
import math


def number(low: float | None = None, high: float | None = None, unit: str = "", *, low_open: bool = True,
           high_open: bool = False, integer: bool = False):
    """An argparse ``type``: a finite number (an integer with ``integer``) in the range from
    ``low`` to ``high`` (either None: unbounded), ends open or closed as given."""
    suffix = f" {unit}" if unit else ""

    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an integer' if integer else 'a number'}, got '{text}'") \
                from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number, got '{text}'")
        below = low is not None and (value <= low if low_open else value < low)
        above = high is not None and (value >= high if high_open else value > high)
        if below or above:
            raise argparse.ArgumentTypeError(f"{text}{suffix} is out of range: {_range(low, high, low_open, high_open)}"
                                             f"{suffix}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


def _range(low, high, low_open: bool, high_open: bool) -> str:
    if low is not None and high is not None:
        return f"expected {'more than' if low_open else 'at least'} {low:g} and {'less than' if high_open else 'at most'} {high:g}"
    if low is not None:
        return f"expected {'more than' if low_open else 'at least'} {low:g}"
    return f"expected {'less than' if high_open else 'at most'} {high:g}"


def numbers(low: float | None = None, high: float | None = None, unit: str = ""):
    """An argparse ``type``: comma-separated numbers, each as :func:`number` checks it."""
    one = number(low, high, unit)

    def parse(text: str) -> list[float]:
        values = [one(part.strip()) for part in text.split(",") if part.strip()]
        if not values:
            raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got '{text}'")
        return values

    parse.__name__ = "numbers"
    return parse
