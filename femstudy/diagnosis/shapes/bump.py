"""A local excess or deficit in time: a Hann window of 0.5–3 s that rises and falls back inside
the cut. Something harder or softer met for a while (the layer's own form, which follows the
drill's geometry, is :mod:`.layer`); on one channel only, reported as ``thrust_only``/``torque_only``.
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.shapes.registry import local_change, register

WIDTHS_S = (0.5, 1.0, 2.0, 3.0)


class Bump:
    kind = "bump"
    width = 1
    scanned = 2
    competes = True
    one_channel_competes = False
    fixed_first = False
    min_size = 0.04

    def candidates(self, ctx):
        t0, t1 = ctx.cut
        return [{"start_s": float(s), "width_s": w} for w in WIDTHS_S
                for s in np.arange(t0, t1 - w, max(ctx.step_s, w / 8))]

    def refine(self, ctx, p):
        return []

    def columns(self, ctx, channel, load, p):
        u = (ctx.t - p["start_s"]) / p["width_s"]
        return [load * np.where((u > 0) & (u < 1), 0.5 * (1 - np.cos(2 * math.pi * u)), 0.0)]

    def interval(self, ctx, p):
        return p["start_s"], p["start_s"] + p["width_s"]

    def size(self, parameters, coefficients, used):
        return max((abs(float(b[0])) for b, u in zip(coefficients, used) if u), default=0.0)

    def describe(self, names, coefficients, parameters, one_channel):
        a, b = parameters["start_s"], parameters["start_s"] + parameters["width_s"]
        return local_change(names, coefficients, one_channel, f"a local change between {a:.2f} and {b:.2f} s", "there")


register(Bump())
