"""An excess that grows with the load itself: the column L²/max L.

A spindle that slows under load raises the feed per revolution, and so the loads, the more the
higher they are; a non-linear sensor does the same. No catalogue mechanism scales with the load's
own size. (A column L beside it would be a free scale, a calibration, and would let the shape take
the place of any mechanism that changes the loads' level.)
"""

from __future__ import annotations

import numpy as np

from femstudy.diagnosis.shapes.registry import amounts, register


class LoadPower:
    kind = "load_power"
    width = 1
    scanned = 0
    competes = True
    one_channel_competes = False
    fixed_first = False
    min_size = 0.04

    def candidates(self, ctx):
        return [{}]

    def columns(self, ctx, channel, load, p):
        return [load ** 2 / max(float(np.max(np.abs(load))), 1e-12)]

    def interval(self, ctx, p):
        return ctx.cut

    def refine(self, ctx, p):
        return []

    def size(self, parameters, coefficients, used):
        return max((abs(float(b[0])) for b, u in zip(coefficients, used) if u), default=0.0)

    def describe(self, names, coefficients, parameters, one_channel):
        return "load_power", (f"an excess that grows with the load itself ({amounts(names, coefficients)} at the "
                              f"peak load), as when the spindle slows under load or the sensor is non-linear.")


register(LoadPower())
