"""A timing mismatch: the events after contact run early or late, and the loads scale.

Columns [L(t_c + (1 + ε)(t − t_c − δ)) − L] (entering whole, coefficient 1) and L, scanned over
the stretch ε (±1–25 %) and a delay δ (±0.5 s: the alignment placed the simulation on the cut's
middle), then refined around the best: a feed or a clock other than the stated one moves
breakthrough and the stop.
"""

from __future__ import annotations

import numpy as np

from femstudy.diagnosis.shapes.registry import WORD, register

STRETCHES = np.geomspace(0.01, 0.25, 24)
DELAYS_S = np.linspace(-0.5, 0.5, 26)


class Timing:
    kind = "timing"
    width = 2
    scanned = 2
    competes = True
    one_channel_competes = False
    fixed_first = True
    min_size = 0.02

    def candidates(self, ctx):
        return [{"stretch": float(e), "delay_s": float(d)} for e in np.concatenate([-STRETCHES, STRETCHES])
                for d in DELAYS_S]

    def columns(self, ctx, channel, load, p):
        t0 = ctx.cut[0]
        retimed = np.interp(t0 + (ctx.t - t0 - p["delay_s"]) * (1 + p["stretch"]), ctx.t, load)
        return [retimed - load, load]

    def interval(self, ctx, p):
        return ctx.cut

    def refine(self, ctx, p):
        """Around a candidate: the stretch ×0.88–1.14 and the delay ± a grid step (applied until the
        gain stops growing, :func:`..outside.shapes`)."""
        step = float(DELAYS_S[1] - DELAYS_S[0])
        ratio = float(STRETCHES[1] / STRETCHES[0])
        return [{"stretch": float(p["stretch"] * f), "delay_s": float(p["delay_s"] + d)}
                for f in np.geomspace(1 / ratio, ratio, 7) for d in np.linspace(-step, step, 9)]

    def size(self, parameters, coefficients, used):
        return abs(parameters["stretch"])

    def describe(self, names, coefficients, parameters, one_channel):
        stretch = 100 * parameters["stretch"]
        scales = " and ".join(f"the {WORD[n]} by {100 * float(coefficients[n][1]):+.1f} %" for n in names)
        return "timing", (f"a timing mismatch: after contact the recording runs {abs(stretch):.1f} % "
                          f"{'ahead of' if stretch > 0 else 'behind'} the simulation (its breakthrough and stop come "
                          f"{'earlier' if stretch > 0 else 'later'}), with {scales}: the feed rate or the recording's "
                          f"clock is not the stated one.")


register(Timing())
