"""The drilling pass of the form-randomised benchmark: feed schedule, lip engagement, cutting loads.

Written for this benchmark alone (it imports nothing from femstudy and nothing from
``bench.independent``). Units: mm, s, N, N·mm, rpm; depth y is measured into the bone from
its outer surface and the drill tip is at depth d(t).

Cutting (Kienzle's law on each lip element): the two lips cut chips of thickness
h = (a/2) sin κ (a the feed per revolution, κ half the point angle); a lip element of width db
carries a force k·h^(1 − m)·db, so the loads grow as a^(1 − m) with the feed. The element at
radius r trails the tip by r·cot κ, so at depth d it cuts the bone at y = d − r cot κ, of
strength w(y): 0 in air, 1 in cortex, ε in cancellous bone, and whatever a decoy layer adds.
Thrust sums the element forces (plus the chisel edge's share at the tip), torque their moments
r·dF. The chip thickness follows the feed per revolution with a first-order lag of a fraction of
a revolution, so the loads vanish within a revolution or two once the feed stops. F_o and T_o
are the thrust and torque fully engaged in cortex at the nominal feed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy.signal import lfilter

#: Lip elements in the engagement sum.
LIP_ELEMENTS = 48


@dataclass(frozen=True)
class Pass:
    """One drilling pass: drill, bone, feed schedule and the cutting law."""

    feed_mm_s: float
    spindle_rpm: float
    diameter_mm: float
    point_angle_deg: float
    cortex_mm: float
    thrust_N: float                       #: F_o
    torque_Nmm: float                     #: T_o
    cancellous_ratio: float = 0.2         #: ε
    chisel_share: float = 0.12            #: share of F_o carried by the chisel edge
    web_fraction: float = 0.15            #: chisel half-length / radius
    kienzle_exponent: float = 0.25        #: m: loads ∝ a^(1 − m)
    lag_revolutions: float = 0.4          #: lag of the chip thickness behind the feed
    approach_s: float = 2.0               #: from the start of the record to contact
    stop_depth_mm: float = 8.0            #: the feed stops at this depth
    dwell_s: float = 0.5
    retract_mm_s: float = 5.0
    feed_error: float = 1.0               #: true feed / stated feed (a decoy)
    layers: tuple = ()                    #: extra (y0, y1, w) layers inside the bone (decoys)

    @property
    def radius_mm(self) -> float:
        return self.diameter_mm / 2

    @property
    def cone_mm(self) -> float:
        return self.radius_mm / math.tan(math.radians(self.point_angle_deg / 2))

    @property
    def breaks_through(self) -> bool:
        return self.stop_depth_mm > self.cortex_mm + self.cone_mm


@dataclass
class Trace:
    """The pass evaluated on a fine time grid, with its events [s] and the depth [mm]."""

    time_s: np.ndarray
    depth_mm: np.ndarray
    chip_factor: np.ndarray               #: (a_lagged / a_nominal)^(1 − m), ≥ 0
    pushing: np.ndarray                   #: 1 while the drill feeds, falling to 0 within a revolution after
    thrust_N: np.ndarray                  #: cutting thrust
    torque_Nmm: np.ndarray                #: cutting torque
    contact_s: float
    full_engagement_s: float
    breakthrough_s: float | None
    exit_s: float | None
    feed_stop_s: float
    retraction_end_s: float
    extras: dict = field(default_factory=dict)

    def column_mm(self, cortex_mm: float, cone_mm: float) -> np.ndarray:
        """Length of the chip column in the cortical hole behind the cone [mm]: the deepest the
        tip has been, within the cortex, less the cone."""
        hole = np.maximum.accumulate(self.depth_mm)
        return np.maximum(np.minimum(hole, cortex_mm) - cone_mm, 0.0)


def strength(p: Pass, y: np.ndarray) -> np.ndarray:
    """Relative strength w(y) of the bone at depth y."""
    w = np.where(y < 0, 0.0, np.where(y < p.cortex_mm, 1.0, p.cancellous_ratio))
    for y0, y1, value in p.layers:
        w = np.where((y >= y0) & (y < y1), value, w)
    return w


def engagement(p: Pass, depth_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Thrust and torque engagement (1 when fully in cortex) at tip depths ``depth_mm``."""
    cot = 1.0 / math.tan(math.radians(p.point_angle_deg / 2))
    web = p.web_fraction * p.radius_mm
    r = web + (p.radius_mm - web) * (np.arange(LIP_ELEMENTS) + 0.5) / LIP_ELEMENTS
    lips = strength(p, depth_mm[:, None] - r[None, :] * cot)
    thrust = (1 - p.chisel_share) * lips.mean(axis=1) + p.chisel_share * strength(p, depth_mm)
    torque = (lips * r[None, :]).sum(axis=1) / r.sum()
    return thrust, torque


def feed_schedule(p: Pass, t: np.ndarray, modulation: np.ndarray | None) -> tuple[np.ndarray, int, int, int]:
    """Depth d(t) and the indices of the feed stop, the start and the end of the retraction."""
    dt = float(t[1] - t[0])
    speed = p.feed_mm_s * p.feed_error * (1.0 + (modulation if modulation is not None else 0.0))
    speed = np.maximum(speed, 0.0) * np.ones_like(t)
    start = -p.feed_mm_s * p.approach_s
    depth = start + np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * dt)])
    i_stop = int(np.searchsorted(depth, p.stop_depth_mm))
    if i_stop >= t.size - 2:
        raise ValueError("the record is too short for the pass")
    depth[i_stop:] = depth[i_stop]
    i_retract = min(i_stop + int(round(p.dwell_s / dt)), t.size - 1)
    back = depth[i_stop] - p.retract_mm_s * (t[i_retract:] - t[i_retract])
    depth[i_retract:] = np.maximum(back, start)
    i_end = i_retract + int(np.argmax(depth[i_retract:] <= start + 1e-9))
    return depth, i_stop, i_retract, i_end


def cut(p: Pass, duration_s: float, step_s: float, modulation: Callable | None = None,
        rpm_of_load: Callable | None = None) -> Trace:
    """The pass on a grid of ``step_s`` from 0 to ``duration_s``.

    ``modulation(t)`` is a relative feed modulation m(t) (feed f(1 + m)); ``rpm_of_load(torque)``
    a spindle speed that depends on the torque (a decoy), solved by fixed-point iteration.
    """
    t = np.arange(0.0, duration_s, step_s)
    m = modulation(t) if modulation is not None else None
    depth, i_stop, i_retract, i_end = feed_schedule(p, t, m)
    speed = np.gradient(depth, step_s)
    speed[i_stop:] = np.minimum(speed[i_stop:], 0.0)
    thrust_w, torque_w = engagement(p, depth)
    a_nominal = p.feed_mm_s * 60.0 / p.spindle_rpm
    rpm = np.full_like(t, p.spindle_rpm)
    for _ in range(8 if rpm_of_load is not None else 1):
        a = np.maximum(speed, 0.0) * 60.0 / rpm
        lag = p.lag_revolutions * 60.0 / float(np.mean(rpm))
        alpha = step_s / (lag + step_s)
        a_lagged = np.maximum(lfilter([alpha], [1.0, alpha - 1.0], a), 0.0)
        chip = (a_lagged / a_nominal) ** (1.0 - p.kienzle_exponent)
        thrust = p.thrust_N * chip * thrust_w
        torque = p.torque_Nmm * chip * torque_w
        if rpm_of_load is None:
            break
        rpm = rpm_of_load(torque)
    pushing = np.clip(a_lagged / (a_nominal * p.feed_error), 0.0, 1.5)
    contact = float(t[int(np.argmax(depth > 0))])
    full = float(t[int(np.argmax(depth >= p.cone_mm))]) if depth.max() >= p.cone_mm else float(t[i_stop])
    breakthrough = exit_ = None
    if depth[i_stop] > p.cortex_mm + p.cone_mm:
        breakthrough = float(t[int(np.argmax(depth >= p.cortex_mm))])
        exit_ = float(t[int(np.argmax(depth >= p.cortex_mm + p.cone_mm))])
    trace = Trace(t, depth, chip, pushing, thrust, torque, contact, full, breakthrough, exit_, float(t[i_stop]),
                  float(t[i_end]))
    trace.extras["rpm"] = rpm
    return trace


def with_stop(p: Pass, stop_depth_mm: float) -> Pass:
    return replace(p, stop_depth_mm=stop_depth_mm)
