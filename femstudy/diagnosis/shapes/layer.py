"""A layer of bone harder or softer than the rest, crossed by the drill's point.

The tip enters a layer of thickness d at t₁ and the feed f carries the point through it. Two
columns per channel, each on the modelled load L_c(t):

- the lips: the lip point at radius ρR trails the tip by ρ times the cone length, so the share
  of the lips inside the layer rises over min(d, cone)/f, stays for |d − cone|/f and falls back;
  the thrust weights the lip uniformly, the torque by radius (the torque's change lags the
  thrust's);
- the chisel edge at the tip, inside the layer for d/f. A twist drill's chisel edge carries a
  share of the thrust that depends on its web (a tenth to more than half), and little torque,
  so this column has its own amplitude.

The sum of a channel's two amplitudes is the layer's change of strength. Layers of 0.25–2 mm
(refined ×0.8–1.25 around the best) whose far face the tip leaves before it leaves the cortex
(or the cut ends), however shortly before: a layer a tenth of a millimetre above the cortex's
far face is a layer, and left out it was named as clogging (docs/diagnosis.md §11). Reported
as a ``bump`` (the contract's kind for a local change); on one channel only, as
``thrust_only``/``torque_only``.
"""

from __future__ import annotations

import numpy as np

from femstudy.diagnosis.shapes.registry import local_change, register

THICKNESS_MM = (0.25, 0.5, 1.0, 2.0)
LIP_POINTS = 24


class Layer:
    kind = "layer"
    width = 2
    scanned = 2
    competes = True
    one_channel_competes = False
    fixed_first = False
    min_size = 0.04

    def _span(self, ctx, d: float) -> tuple[float, float]:
        """Time [s] from the tip's entry to the lips' exit, and the latest entry [s]."""
        w = float((d + ctx.cone_mm) / ctx.feed_mm_s)
        tip_leaves_cortex = min(ctx.cut[1], ctx.cut[0] + ctx.cortex_mm / ctx.feed_mm_s)
        return w, tip_leaves_cortex - d / ctx.feed_mm_s

    def _entries(self, ctx, d: float, starts) -> list[dict]:
        w, latest = self._span(ctx, d)
        return [{"start_s": float(s), "width_s": w, "thickness_mm": float(d)}
                for s in starts(w) if ctx.cut[0] <= s < latest]

    def candidates(self, ctx):
        return [c for d in THICKNESS_MM
                for c in self._entries(ctx, d, lambda w: np.arange(ctx.cut[0], ctx.cut[1], max(ctx.step_s, w / 8)))]

    def refine(self, ctx, p):
        return [c for d in p["thickness_mm"] * np.geomspace(0.8, 1.25, 7)
                for c in self._entries(ctx, d, lambda w: p["start_s"] + np.linspace(-0.5, 0.5, 5)
                                       * max(ctx.step_s, w / 8))]

    def columns(self, ctx, channel, load, p):
        d = p["thickness_mm"]
        travel = ctx.feed_mm_s * (ctx.t - p["start_s"])
        radius = (np.arange(LIP_POINTS) + 0.5) / LIP_POINTS
        below_top = travel[:, None] - radius[None, :] * ctx.cone_mm
        inside = (below_top >= 0) & (below_top <= d)
        weight = radius if ctx.channels[channel] == "torque_Nmm" else np.ones_like(radius)
        return [load * (inside @ weight / weight.sum()), load * ((travel >= 0) & (travel <= d))]

    def interval(self, ctx, p):
        return p["start_s"], p["start_s"] + p["width_s"]

    def size(self, parameters, coefficients, used):
        return max((abs(float(b[0] + b[1])) for b, u in zip(coefficients, used) if u), default=0.0)

    def describe(self, names, coefficients, parameters, one_channel):
        a, b = parameters["start_s"], parameters["start_s"] + parameters["width_s"]
        strength = {n: [float(coefficients[n][0] + coefficients[n][1])] for n in names}
        return local_change(names, strength, one_channel,
                            f"a layer {parameters['thickness_mm']:.2f} mm thick, met by the point from {a:.2f} to {b:.2f} s",
                            "inside it")


register(Layer())
