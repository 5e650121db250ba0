"""A step: the loads change by a fraction at one instant in the cut and stay changed.

Columns L·H(t − t₀), t₀ scanned through the cut (away from contact and the stop by three Gaussian
widths: a step there is the simulation's own timing). On one channel only it is reported as
``thrust_only``/``torque_only``. No catalogue mechanism changes the loads at one instant: a chip
plug breaking off, a crack, a slip.
"""

from __future__ import annotations

import numpy as np

from femstudy.diagnosis.shapes.registry import WORD, amounts, register


class Step:
    kind = "step"
    width = 1
    scanned = 1
    competes = True
    one_channel_competes = False
    fixed_first = False
    min_size = 0.03

    def candidates(self, ctx):
        t0, t1 = ctx.cut
        edge = 3 * ctx.sigma_s
        return [{"time_s": float(s)} for s in np.arange(t0 + edge, t1 - edge, ctx.step_s)]

    def columns(self, ctx, channel, load, p):
        return [load * (ctx.t >= p["time_s"])]

    def interval(self, ctx, p):
        return p["time_s"], ctx.cut[1]

    def refine(self, ctx, p):
        return []

    def size(self, parameters, coefficients, used):
        return max((abs(float(b[0])) for b, u in zip(coefficients, used) if u), default=0.0)

    def describe(self, names, coefficients, parameters, one_channel):
        t = parameters["time_s"]
        if one_channel:
            word = WORD[names[0]]
            return (f"{word}_only", f"{word} only: from {t:.2f} s the {word} changes by "
                    f"{100 * float(coefficients[names[0]][0]):+.1f} % while the other channel follows the model: "
                    f"friction on the drill's body or in the flutes that loads one channel and not the other, or a "
                    f"change in one sensor channel.")
        return "step", (f"a step at {t:.2f} s: {amounts(names, coefficients)} from then on. No catalogue mechanism "
                        f"changes the loads at one instant (a chip plug breaking off, a crack, a slip).")


register(Step())
