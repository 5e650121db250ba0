"""The simulation a recording is diagnosed against: a simulated trace or a femstudy load model.

Both are functions of *simulation time* τ [s], the time at which the simulated drill reaches a
depth at the nominal feed f: contact at ``contact_s``, depth d = f (τ − contact_s) until the
feed stops at ``stop_s``; then the loads vanish. The diagnosis maps the recording's time t onto
τ (a constant shift, plus the feed pulsation's depth lead when that mechanism is fitted).

- :class:`TraceSimulation`: a trace in the recording format on its own time base, read with
  the same reader and linearly interpolated. Before its first sample (after its last) it is
  continued by zero only when it starts (ends) unloaded — below ``UNLOADED`` of its peak —
  because then zero is what it means (the drill is off the bone); otherwise the diagnosis is
  restricted to the span it covers. Its contact is where its first loaded samples extrapolate
  to zero (the entry ramp is linear in depth), its stop the deepest point of its ``depth_mm``
  column, or else where its final fall begins (the loads follow the feed per revolution down
  within a revolution or a few once the feed stops, :func:`_final_fall`).
- :class:`ModelSimulation`: a load model of :mod:`femstudy.drilling.history` for the
  recording's feed, speed, drill and cortex, started at the recording's contact and stopped at
  a depth that the fit adjusts (the stop of a real rig is not at a known depth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from femstudy.drilling.history import DrillingConditions, evaluate
from femstudy.errors import require

if TYPE_CHECKING:
    from femstudy.diagnosis.timing import TraceEvents

#: A trace is "unloaded" at an edge when |thrust| there is below this fraction of its peak.
UNLOADED = 0.01
#: Loads below this fraction of the peak count as zero when contact and stop are located.
NONZERO = 1e-6
#: The final fall of a trace: the thrust falls by more than this share of itself per revolution
#: (:func:`_final_fall`).
FALL_RATE = 0.3
#: A trace whose first load is below this fraction of its peak, and which rises after it, starts at
#: contact (a finite first load is the chisel edge's or the first lip element's): before it, zero.
STARTS_AT_CONTACT = 0.25
#: A trace that ends loaded, below this fraction of its peak and after falling from it (in
#: cancellous bone past breakthrough), ends at its feed stop: the loads vanish one revolution later.
ENDS_AT_STOP = 0.4


def _zero_crossing(t: np.ndarray, F: np.ndarray, k: int, side: int) -> float:
    """Where the straight line through the edge samples k and k − side (the first loaded ones)
    reaches zero, kept between k and its unloaded neighbour k + side."""
    inner = k - side
    if not 0 <= inner < t.size or not 0 <= k + side < t.size or F[inner] == F[k]:
        return float(t[min(max(k + side, 0), t.size - 1)] if 0 <= k + side < t.size else t[k])
    crossing = t[k] - F[k] * (t[inner] - t[k]) / (F[inner] - F[k])
    lo, hi = sorted((float(t[k]), float(t[k + side])))
    return float(np.clip(crossing, lo, hi))


def _final_fall(t: np.ndarray, F: np.ndarray, peak: float, revolution_s: float) -> float:
    """Where the trace's final fall begins: going back from where the loads vanish, the first
    instant the thrust no longer falls by ``FALL_RATE`` of itself per revolution. Once the feed
    stops the loads follow the feed per revolution down within a revolution or a few (femstudy's
    load models in one, linearly; a lagged chip thickness exponentially); a breakthrough's fall
    takes the cone's exit time l/f, far longer, and is not taken for it."""
    k = int(np.flatnonzero(F > UNLOADED * peak)[-1])
    slope = np.gradient(F, t)
    i = k
    while i > 0 and slope[i - 1] < -FALL_RATE * max(F[i - 1], UNLOADED * peak) / revolution_s:
        i -= 1
    return float(t[i])


def _fall(tau, stop_s: float, spindle_rpm: float):
    """Loads × clip(1 − (τ − stop)·N/60, 0, 1): zero one revolution after the feed stops."""
    return np.clip(1.0 - (tau - stop_s) * spindle_rpm / 60.0, 0.0, 1.0)


@dataclass
class TraceSimulation:
    """A simulated trace: thrust [N], torque [N·mm] or None, against time [s]."""

    time_s: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray | None
    spindle_rpm: float
    depth_mm: np.ndarray | None = None
    label: str = "simulation"
    note: str = ""               # how the trace was placed on the recording's clock, if it was
    events: "TraceEvents | None" = None   # once known (contact, breakthrough, cortex)

    def __post_init__(self) -> None:
        t, F = self.time_s, np.abs(self.thrust_N)
        peak = float(F.max())
        require(peak > 0, f"{self.label} has no load: its thrust is zero throughout")
        self.zero_before = bool(F[0] <= UNLOADED * peak)
        self.zero_after = bool(F[-1] <= UNLOADED * peak)
        loaded = np.flatnonzero(F > NONZERO * peak)
        self.contact_s = _zero_crossing(t, F, loaded[0], -1) if self.zero_before else float(t[0])
        if not self.zero_before and F[0] <= STARTS_AT_CONTACT * peak and F[: max(t.size // 4, 2)].max() > 2 * F[0]:
            self.zero_before = True   # it starts at contact: the drill was in air before
        if self.depth_mm is not None and np.ptp(self.depth_mm) > 0:
            self.stop_s = float(t[int(np.argmax(self.depth_mm))])
        elif self.zero_after:
            self.stop_s = _final_fall(t, F, peak, 60.0 / self.spindle_rpm)
        elif F[-1] <= ENDS_AT_STOP * peak and F[-1] < (1 - ENDS_AT_STOP) * float(F[loaded[0]:].max()):
            # it ends after the loads fell (breakthrough into cancellous bone): at the feed stop,
            # where the loads vanish within one revolution
            self.stop_s = float(t[-1])
            self.ends_at_stop = True
            self.zero_after = True
        else:
            self.stop_s = math.inf
        self.stop_s = max(self.stop_s, self.contact_s)

    stop_is_parameter = False
    ends_at_stop = False

    @classmethod
    def from_recording(cls, rec, spindle_rpm: float) -> "TraceSimulation":
        """A simulated trace read with :func:`femstudy.recordings.read_recording`."""
        return cls(rec.time_s, rec.thrust_N, rec.torque_Nmm, spindle_rpm, rec.depth_mm,
                   label=f"simulation {rec.name}")

    @property
    def has_torque(self) -> bool:
        return self.torque_Nmm is not None

    def span(self) -> tuple[float, float]:
        """Times [s] over which the trace means something (infinite where continued by zero)."""
        return (-math.inf if self.zero_before else float(self.time_s[0]),
                math.inf if self.zero_after else float(self.time_s[-1]))

    def loads(self, tau: np.ndarray, stop_s: float | None = None):
        """Thrust [N] and torque [N·mm] (or None) at simulation times τ."""
        left = 0.0 if self.zero_before else None
        right = 0.0 if self.zero_after and not self.ends_at_stop else None
        F = np.interp(tau, self.time_s, self.thrust_N, left=left, right=right)
        T = None if self.torque_Nmm is None else np.interp(tau, self.time_s, self.torque_Nmm,
                                                           left=left, right=right)
        if self.ends_at_stop:
            fall = _fall(tau, float(self.time_s[-1]), self.spindle_rpm)
            F = F * fall
            T = None if T is None else T * fall
        return F, T


@dataclass
class ModelSimulation:
    """A load model ("allotta", "clogging", ...) started at ``contact_s``."""

    model: str
    conditions: DrillingConditions
    contact_s: float
    stop_depth_mm: float
    with_torque: bool = True
    max_depth_mm: float | None = None

    stop_is_parameter = True

    def __post_init__(self) -> None:
        deepest = max(self.max_depth_mm or 0.0, 2 * self.stop_depth_mm, self.conditions.cortex_mm + 5.0)
        self._depth = np.linspace(0.0, deepest, int(deepest / 0.002) + 1)
        history = evaluate(self.model, self.conditions, self._depth / self.conditions.feed_mm_s)
        self._F = history.thrust_N
        self._T = history.torque_Nmm
        self.with_torque = self.with_torque and bool(np.all(np.isfinite(self._T)))

    @property
    def has_torque(self) -> bool:
        return self.with_torque

    @property
    def spindle_rpm(self) -> float:
        return self.conditions.spindle_rpm

    @property
    def stop_s(self) -> float:
        return self.contact_s + self.stop_depth_mm / self.conditions.feed_mm_s

    def span(self) -> tuple[float, float]:
        return -math.inf, math.inf

    def loads(self, tau: np.ndarray, stop_s: float | None = None):
        stop = self.stop_s if stop_s is None else stop_s
        f = self.conditions.feed_mm_s
        d = f * np.clip(np.minimum(tau, stop) - self.contact_s, 0.0, None)
        fall = _fall(tau, stop, self.spindle_rpm)
        F = np.interp(d, self._depth, self._F) * fall
        T = np.interp(d, self._depth, self._T) * fall if self.with_torque else None
        return F, T
