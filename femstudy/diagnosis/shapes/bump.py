"""A local excess or deficit: a Hann window in time, or the share of the lips inside a layer.

A layer of thickness d entered by the tip at t₁: the lip point at radius ρR follows ρ·(cone
length) behind the tip, so the share of the lips inside the layer rises over min(d, cone)/f,
stays for |d − cone|/f and falls back; the thrust weights the lip uniformly, the torque by radius
(so the torque's bump lags the thrust's). Hann windows of 0.5–3 s, layers of 0.25–2 mm (refined
×0.8–1.25 around the best). A bump rises and falls back inside the cut, or at least half its fall
comes before the cut ends or the tip leaves the cortex. A harder or softer layer of bone; on one
channel only, reported as ``thrust_only``/``torque_only``.
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.shapes.registry import WORD, amounts, register

WIDTHS_S = (0.5, 1.0, 2.0, 3.0)
THICKNESS_MM = (0.25, 0.5, 1.0, 2.0)
LIP_POINTS = 24


class Bump:
    kind = "bump"
    width = 1
    scanned = 2
    competes = True
    one_channel_competes = False
    fixed_first = False
    min_size = 0.04

    def _layer(self, ctx, d: float) -> tuple[float, float]:
        """Width [s] of a layer of thickness d and the latest tip entry that keeps half its fall inside."""
        w = float((d + ctx.cone_mm) / ctx.feed_mm_s)
        t_layers = min(ctx.cut[1], ctx.cut[0] + ctx.cortex_mm / ctx.feed_mm_s)
        return w, t_layers - w + min(d, ctx.cone_mm) / ctx.feed_mm_s / 2

    def candidates(self, ctx):
        t0, t1 = ctx.cut
        out = [{"start_s": float(s), "width_s": w} for w in WIDTHS_S
               for s in np.arange(t0, t1 - w, max(ctx.step_s, w / 8))]
        for d in THICKNESS_MM:
            w, latest = self._layer(ctx, d)
            out += [{"start_s": float(s), "width_s": w, "thickness_mm": d}
                    for s in np.arange(t0, latest, max(ctx.step_s, w / 8))]
        return out

    def refine(self, ctx, p):
        if "thickness_mm" not in p:
            return []
        out = []
        for d in p["thickness_mm"] * np.geomspace(0.8, 1.25, 7):
            w, latest = self._layer(ctx, d)
            out += [{"start_s": float(s), "width_s": w, "thickness_mm": float(d)}
                    for s in p["start_s"] + np.linspace(-0.5, 0.5, 5) * max(ctx.step_s, w / 8)
                    if ctx.cut[0] <= s < latest]
        return out

    def columns(self, ctx, channel, load, p):
        t = ctx.t
        if "thickness_mm" not in p:
            u = (t - p["start_s"]) / p["width_s"]
            return [load * np.where((u > 0) & (u < 1), 0.5 * (1 - np.cos(2 * math.pi * u)), 0.0)]
        radius = (np.arange(LIP_POINTS) + 0.5) / LIP_POINTS
        below_top = ctx.feed_mm_s * (t[:, None] - p["start_s"]) - radius[None, :] * ctx.cone_mm
        inside = (below_top >= 0) & (below_top <= p["thickness_mm"])
        weight = radius if ctx.channels[channel] == "torque_Nmm" else np.ones_like(radius)
        return [load * (inside @ weight / weight.sum())]

    def interval(self, ctx, p):
        return p["start_s"], p["start_s"] + p["width_s"]

    def size(self, parameters, coefficients, used):
        return max((abs(float(b[0])) for b, u in zip(coefficients, used) if u), default=0.0)

    def describe(self, names, coefficients, parameters, one_channel):
        a, b = parameters["start_s"], parameters["start_s"] + parameters["width_s"]
        only = f", {WORD[names[0]]} only" if one_channel else ""
        kind = f"{WORD[names[0]]}_only" if one_channel else "bump"
        return kind, (f"a local change between {a:.2f} and {b:.2f} s: {amounts(names, coefficients)} there{only}, "
                      f"as from a harder or softer layer of bone.")


register(Bump())
