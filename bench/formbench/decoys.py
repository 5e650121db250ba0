"""Decoys: what changes a recording and is none of the four catalogue mechanisms.

Each is physics or instrumentation reported in the bone-drilling literature, which a simulation
of the cut leaves out and a diagnosis must describe rather than name as one of the four:

==================  =====================================================================================
kind                what the recording has (the simulation has none of it)
==================  =====================================================================================
chip_break          thrust and torque drop by 10–25 % at one instant mid-cut (a chip plug breaks off)
hard_layer          a 0.4–1.5 mm layer of the cortex 25–60 % stronger (an osteon-dense band)
soft_layer          a 0.4–1.5 mm layer 30–60 % weaker (a resorption cavity, a vascular canal)
spindle_slowdown    the spindle slows under load, N₀/(1 + κT/T_o), 10–25 % at full load (Jacobs et al.)
feed_error          the true feed is 6–15 % off the stated one
clock_error         the logger's clock runs 3–8 % fast or slow
thrust_wobble       thrust alone × (1 + 6–15 % sin 2πft) in contact (runout, misalignment: thesis §4.3)
torque_friction     torque alone changes by ±12–30 % from one instant on (the drill's body rubbing)
second_cortex       bicortical drilling: after 1.5–4 mm of cancellous bone the drill enters a second
                    cortex (thesis §4.1.2)
fixture_vibration   both channels oscillate at 0.5–3 Hz but not as one feed (torque 0–40 % of the
                    thrust's relative amplitude, 60–120° behind): the vice or the specimen vibrates
air_knock           a knock on the fixture in air before contact or after retraction (a decaying
                    ringing of 20–60 % of F_o)
tare_jump           the amplifier's zero jumps by 4–10 % of the load in air before contact and stays
second_touch        after retraction the drill touches the bone again for 0.3–0.8 s
polarity            one channel is written with the opposite sign
swapped             the thrust and torque columns are swapped
cross_talk          the torque channel picks up 8–20 % (of its own load) from the thrust
unit_scale          a channel written in another unit than its column says (kN, daN, lbf or N·m)
saturation          the converter's range is 80–92 % of the peak thrust: the top is clipped
==================  =====================================================================================
"""

from __future__ import annotations

import math

import numpy as np

#: Unit mistakes: (channel, factor written / true, what the column says against what it holds).
UNIT_MISTAKES = (("thrust_N", 1e-3, "kN written as N"), ("thrust_N", 0.1, "daN written as N"),
                 ("thrust_N", 1 / 4.44822, "lbf written as N"), ("torque_Nmm", 1e-3, "N·m written as N·mm"))


def smooth_step(t: np.ndarray, t0: float, rise_s: float) -> np.ndarray:
    return 0.5 * (1 + np.tanh((t - t0) / max(rise_s / 3, 1e-4)))


def ringing(t: np.ndarray, t0: float, amplitude: float, hz: float, decay_s: float) -> np.ndarray:
    """A knock: a damped oscillation from t0."""
    u = np.clip(t - t0, 0.0, None)
    return np.where(t >= t0, amplitude * np.exp(-u / decay_s) * np.sin(2 * math.pi * hz * u), 0.0)
