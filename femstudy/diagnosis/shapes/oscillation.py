"""An oscillation that is not the feed pulsation's: L·sin 2πft, L·cos 2πft in the cut.

Scanned over 0.2–4 Hz (at least two periods in the cut, and below 80 % of the analysis instants'
Nyquist frequency). Carried by both channels in proportion
it is the feed pulsation's own form, so it competes with the mechanisms only on one channel (a
vibration of the fixture or the specimen, a misaligned drill loading one channel).
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.shapes.registry import WORD, register

FREQUENCIES_HZ = np.geomspace(0.2, 4.0, 90)
#: Fewest periods in the cut: fewer are a local change (a bump), not an oscillation.
MIN_PERIODS = 2.0


class Oscillation:
    kind = "oscillation"
    width = 2
    scanned = 1
    competes = True
    one_channel_competes = True
    fixed_first = False
    min_size = 0.03

    def candidates(self, ctx):
        return [{"frequency_hz": float(f)} for f in FREQUENCIES_HZ
                if f * (ctx.cut[1] - ctx.cut[0]) >= MIN_PERIODS and f <= ctx.highest_hz]

    def columns(self, ctx, channel, load, p):
        w = 2 * math.pi * p["frequency_hz"] * ctx.t
        return [load * ctx.in_cut * np.sin(w), load * ctx.in_cut * np.cos(w)]

    def interval(self, ctx, p):
        return ctx.cut

    def refine(self, ctx, p):
        return []

    def size(self, parameters, coefficients, used):
        return max((float(np.hypot(*b[:2])) for b, u in zip(coefficients, used) if u), default=0.0)

    def describe(self, names, coefficients, parameters, one_channel):
        amp = {n: 100 * float(np.hypot(*coefficients[n][:2])) for n in names}
        where = f"{WORD[names[0]]} only" if one_channel else "both channels"
        return "oscillation", (f"an oscillation at {parameters['frequency_hz']:.2f} Hz in {where}, ±"
                               + " and ±".join(f"{amp[n]:.1f} % of the {WORD[n]}" for n in names)
                               + (": a feed pulsation would move thrust and torque together, so this is another "
                                  "vibration (fixture, bone support, misalignment)." if one_channel else
                                  ", not of the feed pulsation's form (not one modulation of both loads with the "
                                  "depth running ahead)."))


register(Oscillation())
