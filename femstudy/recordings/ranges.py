"""What a drilling recording's values can physically be: refused beyond, in one line.

A surgical drill in bone pushes with tens of newtons and turns with hundreds of N·mm (thesis
Table 4-1: thrust up to about 60 N); a channel reaching 10 kN or 100 N·m has a wrong unit or
is not a drilling recording, and one of 1e300 N would carry on to overflow every fit. A
thrust or torque channel that never changes recorded nothing (a dead sensor, an unplugged
cable): the thrust is checked by :func:`femstudy.recordings.reader.check_recording`, the
torque here, so that a dead torque channel is not compared as if it were a measurement (the
side forces and the depth, which no analysis needs, may well be constant).
"""

from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from femstudy.errors import UserError

#: Largest magnitude of each channel, in femstudy's units (N, N·mm, mm).
MAX_MAGNITUDE = {"thrust": 1e4, "torque": 1e5, "fx": 1e4, "fy": 1e4, "depth": 1e3}
UNIT_WORDS = {"thrust": "N", "torque": "N·mm", "fx": "N", "fy": "N", "depth": "mm"}


def check_values(rec, where: Callable[[int], str], columns: Mapping[str, tuple[str, str]],
                 hint: str = "is the column's unit right?") -> None:
    """Raise :class:`UserError` for a channel beyond :data:`MAX_MAGNITUDE` or a constant
    torque; ``where(row)`` names a row in the
    file's terms, ``columns`` maps a quantity to its column's (name, unit) as written, ``hint``
    says what to look at."""
    name = rec.name
    for quantity, values in (("thrust", rec.thrust_N), ("torque", rec.torque_Nmm), ("depth", rec.depth_mm),
                             ("fx", rec.fx_N), ("fy", rec.fy_N)):
        if values is None or values.size == 0:
            continue
        label = columns.get(quantity, (quantity, ""))[0]
        row = int(np.argmax(np.abs(values)))
        if abs(values[row]) > MAX_MAGNITUDE[quantity]:
            raise UserError(f"recording {name}: {label} reaches {values[row]:.3g} {UNIT_WORDS[quantity]} at {where(row)}; "
                            f"a drilling recording stays within ±{MAX_MAGNITUDE[quantity]:g} {UNIT_WORDS[quantity]} "
                            f"({hint})")
        if quantity == "torque" and np.ptp(values) == 0:
            raise UserError(f"recording {name}: {label} is constant ({values[0]:g} {UNIT_WORDS[quantity]}), so its "
                            f"sensor recorded nothing; remove the column, or name the right one with --columns "
                            f"{quantity}=NAME")
