"""Load history of one drilling pass: lips and chisel edge over bone layers, chip evacuation.

Units: mm, s, N, N·mm, rpm. Depth y is measured into the bone from its outer surface; the
tip is at depth d(t).

Cutting (thesis §2.4, §3.1, in this module's own form). Each of the two lips removes a chip
of thickness a/2, a the feed per revolution. A lip element at radius r sits at depth
y = d − r/tan κ (κ half the point angle) and cuts material of relative strength w(y): 0 in
air, 1 in cortex, ε in cancellous bone. The lips' thrust is proportional to the strength
averaged over the lip length, the torque to its r-weighted average; the chisel edge, inside
the web radius c, adds a share χ of the thrust. Both loads grow as a^0.8 with the feed
(the feed exponent of the thesis's Eqs 2.9-2.10), not linearly, and follow the feed per
revolution with a lag of half a revolution. Full engagement in cortex at the nominal feed
gives the thrust F_o and the torque T_o.

Chip evacuation (thesis §3.2, Eqs 3.16/3.19 in spirit): the chip column in the flutes is the
length of hole in cortex behind the cone, L = min(d_max, h) − l. Clogging starts only once
that column exceeds L0; with z = max(L − L0, 0)/D the extra thrust is g·F_o(e^{pz} − 1) and
the extra torque k_c times it. The packed chips push only while the drill feeds: the term is
scaled by tanh(3a/a_nom)/tanh 3.

Thermal softening: cutting loads × 1 − s·x/(1 + x), x = (t − t_contact)/τ_s (hyperbolic
approach to 1 − s, not exponential).

Feed pulsation: the feed is f(1 + m(t)) with m a stick-slip sawtooth (slow rise, fast slip)
or a sine whose frequency sweeps linearly in time; the depth integrates it.

Spindle slow-down (a decoy): N = N0/(1 + κ_N T/T_o); the feed per revolution grows as the
spindle slows, and so do the loads (solved by fixed-point iteration).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import lfilter

#: internal time step [s] of the load history (4 kHz)
FINE_STEP_S = 2.5e-4


@dataclass(frozen=True)
class Pulsation:
    """Feed modulation m(t): ``kind`` is "sawtooth" (stick-slip) or "sweep" (chirp)."""

    kind: str
    amplitude: float
    start_hz: float
    end_hz: float
    phase_rad: float = 0.0

    def modulation(self, t: np.ndarray, duration_s: float) -> np.ndarray:
        if self.kind == "sawtooth":
            # rises over 85 % of the period, slips back over 15 %
            u = np.mod(self.start_hz * t + self.phase_rad / (2 * math.pi), 1.0)
            rise = 0.85
            wave = np.where(u < rise, -1 + 2 * u / rise, 1 - 2 * (u - rise) / (1 - rise))
            return self.amplitude * wave
        if self.kind == "sweep":
            k = (self.end_hz - self.start_hz) / duration_s
            return self.amplitude * np.sin(2 * math.pi * (self.start_hz * t + 0.5 * k * t * t) + self.phase_rad)
        raise ValueError(self.kind)


@dataclass(frozen=True)
class Clogging:
    """Chip-evacuation load: g·F_o(e^{pz} − 1) thrust, k_c times that torque [N·mm/N = mm]."""

    exponent: float
    gain: float = 1.0
    onset_mm: float = 0.0
    torque_per_thrust_mm: float = 0.6


@dataclass(frozen=True)
class Pass:
    """One drilling pass: drill, bone, feed schedule, and the physics switched on."""

    feed_mm_s: float
    spindle_rpm: float
    diameter_mm: float
    point_angle_deg: float
    cortex_mm: float
    thrust_N: float                  #: F_o, full engagement in cortex at the nominal feed
    torque_Nmm: float                #: T_o
    cancellous_ratio: float = 0.2    #: ε = cancellous / cortical strength
    chisel_share: float = 0.15       #: χ, the chisel edge's share of the thrust
    web_fraction: float = 0.12       #: chisel half-length / radius
    approach_s: float = 2.0          #: time from the start to contact at the nominal feed
    stop_depth_mm: float = 8.0       #: depth at which the feed stops
    dwell_s: float = 0.5             #: time at the stop before retraction
    retract_mm_s: float = 5.0
    clogging: Clogging | None = None
    softening: tuple[float, float] | None = None     #: (s, τ_s [s])
    pulsation: Pulsation | None = None
    spindle_droop: float = 0.0       #: κ_N (decoy)
    feed_scale: float = 1.0          #: true feed / stated feed (decoy)
    inclusion: tuple[float, float, float] | None = None   #: (y0, y1, strength) in cortex (decoy)
    step: tuple[float, float] | None = None               #: (t, fractional drop) (decoy)
    torque_change: tuple[float, float, float] | None = None  #: (t, fraction, rise time) (decoy)
    thrust_wobble: tuple[float, float, float] | None = None  #: (Hz, fraction, phase) (decoy)

    @property
    def radius_mm(self) -> float:
        return self.diameter_mm / 2

    @property
    def cone_mm(self) -> float:
        """Length l of the drill point's cone [mm]."""
        return self.radius_mm / math.tan(math.radians(self.point_angle_deg / 2))

    def without(self, *names: str) -> "Pass":
        """This pass with the named physics switched off (what a simulation leaves out)."""
        off = {"clogging": None, "softening": None, "pulsation": None, "spindle_droop": 0.0,
               "feed_scale": 1.0, "inclusion": None, "step": None, "torque_change": None,
               "thrust_wobble": None}
        return replace(self, **{n: off[n] for n in names})


@dataclass(frozen=True)
class History:
    """The load history on the fine grid, and its events [s]."""

    time_s: np.ndarray
    depth_mm: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray
    spindle_phase_rad: np.ndarray
    contact_s: float
    full_engagement_s: float
    breakthrough_s: float | None     #: the tip leaves the cortex (the loads start to fall)
    exit_s: float | None             #: the whole point has left the cortex
    feed_stop_s: float
    retraction_end_s: float


def _layers(p: Pass) -> list[tuple[float, float, float]]:
    """(y0, y1, w) from the surface down: cortex (with an inclusion), then cancellous bone."""
    cortex = [(0.0, p.cortex_mm, 1.0)]
    if p.inclusion is not None:
        y0, y1, w = p.inclusion
        cortex = [(0.0, y0, 1.0), (y0, y1, w), (y1, p.cortex_mm, 1.0)]
    return cortex + [(p.cortex_mm, 1e9, p.cancellous_ratio)]


def _overlap(lo: np.ndarray, hi: np.ndarray, a: float, b: float, power: int) -> np.ndarray:
    """∫ r^(power−1) dr·power over [lo, hi] ∩ [a, b], i.e. the length (1) or r² span (2)."""
    lo_c = np.clip(lo, a, b)
    hi_c = np.clip(hi, a, b)
    return np.maximum(hi_c**power - lo_c**power, 0.0)


def engagement(p: Pass, depth_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Strength averaged over the lips (thrust), r-weighted (torque), and over the chisel edge."""
    r_max = p.radius_mm
    web = p.web_fraction * r_max
    tan_k = math.tan(math.radians(p.point_angle_deg / 2))
    lips_f = np.zeros_like(depth_mm)
    lips_t = np.zeros_like(depth_mm)
    chisel = np.zeros_like(depth_mm)
    for y0, y1, w in _layers(p):
        # radii whose lip point lies in [y0, y1): d − r/tanκ ∈ [y0, y1)  ⇔  r ∈ ((d − y1)tanκ, (d − y0)tanκ]
        lo = (depth_mm - y1) * tan_k
        hi = (depth_mm - y0) * tan_k
        lips_f += w * _overlap(lo, hi, web, r_max, 1) / (r_max - web)
        lips_t += w * _overlap(lo, hi, web, r_max, 2) / (r_max**2 - web**2)
        chisel += w * _overlap(lo, hi, 0.0, web, 1) / web
    return lips_f, lips_t, chisel


def _feed_schedule(p: Pass, t: np.ndarray) -> tuple[np.ndarray, int, int, int]:
    """Depth d(t) [mm] and the indices of the feed stop, retraction start and end."""
    dt = FINE_STEP_S
    f_true = p.feed_mm_s * p.feed_scale
    m = p.pulsation.modulation(t, float(t[-1])) if p.pulsation else 0.0
    speed = f_true * (1.0 + m) * np.ones_like(t)
    start = -p.feed_mm_s * p.approach_s
    depth = start + np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * dt)])
    i_stop = int(np.searchsorted(depth, p.stop_depth_mm))
    if i_stop >= t.size - 1:
        raise ValueError("the recording is too short for the pass")
    depth[i_stop:] = depth[i_stop]
    i_retract = i_stop + int(round(p.dwell_s / dt))
    back = depth[i_stop] - p.retract_mm_s * (t[i_retract:] - t[i_retract])
    depth[i_retract:] = np.maximum(back, start)
    i_end = i_retract + int(np.argmax(depth[i_retract:] <= start + 1e-9))
    return depth, i_stop, i_retract, i_end


def history(p: Pass, duration_s: float) -> History:
    """Evaluate the pass on the fine grid from 0 to ``duration_s``."""
    t = np.arange(0.0, duration_s + FINE_STEP_S / 2, FINE_STEP_S)
    depth, i_stop, i_retract, i_end = _feed_schedule(p, t)
    speed = np.gradient(depth, FINE_STEP_S)
    speed[i_stop:] = np.minimum(speed[i_stop:], 0.0)
    lips_f, lips_t, chisel = engagement(p, depth)
    hole = np.maximum.accumulate(depth)
    l_cone = p.cone_mm
    a_nom = p.feed_mm_s * 60.0 / p.spindle_rpm

    def lagged(x: np.ndarray, rpm: np.ndarray | float) -> np.ndarray:
        tau = 0.5 * 60.0 / float(np.mean(rpm))
        alpha = FINE_STEP_S / (tau + FINE_STEP_S)
        return lfilter([alpha], [1, -(1 - alpha)], x)

    contact_i = int(np.argmax(depth > 0))
    t_contact = float(t[contact_i])
    soft = np.ones_like(t)
    if p.softening is not None:
        s, tau_s = p.softening
        x = np.maximum(t - t_contact, 0.0) / tau_s
        soft = 1 - s * x / (1 + x)

    clog_f = np.zeros_like(t)
    if p.clogging is not None:
        c = p.clogging
        column = np.maximum(np.minimum(hole, p.cortex_mm) - l_cone, 0.0)
        z = np.maximum(column - c.onset_mm, 0.0) / p.diameter_mm
        clog_f = c.gain * p.thrust_N * np.expm1(c.exponent * z)

    rpm = np.full_like(t, p.spindle_rpm)
    for _ in range(6 if p.spindle_droop else 1):
        a = np.maximum(speed, 0.0) * 60.0 / rpm
        a_eff = np.maximum(lagged(a, rpm), 0.0)
        feed_law = (a_eff / a_nom) ** 0.8
        pushing = np.tanh(3 * a_eff / a_nom) / math.tanh(3)
        thrust = p.thrust_N * feed_law * soft * ((1 - p.chisel_share) * lips_f + p.chisel_share * chisel)
        torque = p.torque_Nmm * feed_law * soft * lips_t
        thrust = thrust + clog_f * pushing
        torque = torque + (p.clogging.torque_per_thrust_mm if p.clogging else 0.0) * clog_f * pushing
        if not p.spindle_droop:
            break
        rpm = p.spindle_rpm / (1 + p.spindle_droop * torque / p.torque_Nmm)

    if p.step is not None:
        t_step, drop = p.step
        thrust = thrust * np.where(t >= t_step, 1 - drop, 1.0)
        torque = torque * np.where(t >= t_step, 1 - drop, 1.0)
    if p.torque_change is not None:
        t_on, frac, rise = p.torque_change
        torque = torque * (1 + frac * 0.5 * (1 + np.tanh((t - t_on) / (rise / 3))))
    if p.thrust_wobble is not None:
        hz, frac, phase = p.thrust_wobble
        thrust = thrust * (1 + frac * np.sin(2 * math.pi * hz * t + phase))

    phase = 2 * math.pi * np.concatenate([[0.0], np.cumsum(0.5 * (rpm[1:] + rpm[:-1]) / 60.0 * FINE_STEP_S)])
    full_i = int(np.argmax(depth >= l_cone))
    reached = depth[i_stop]
    breakthrough = exit_ = None
    if reached > p.cortex_mm + l_cone:
        breakthrough = float(t[int(np.argmax(depth >= p.cortex_mm))])
        exit_ = float(t[int(np.argmax(depth >= p.cortex_mm + l_cone))])
    return History(t, depth, thrust, torque, phase, t_contact, float(t[full_i]), breakthrough, exit_,
                   float(t[i_stop]), float(t[i_end]))
