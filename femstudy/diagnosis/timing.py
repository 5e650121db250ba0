"""Timing and geometry from the simulation: its events, and its clock against the recording's.

A simulated trace is noise-free and says where the cut is. So when one is given, the
diagnosis takes contact, full engagement, breakthrough and the cortex thickness from it, and
places it on the recording's clock by correlation, instead of detecting the cut in a noisy
recording (which can fail: a drifting low-feed recording, or clogging that keeps the loads
high until the drill stops, which looks like a retraction).

Events of a trace (:func:`trace_events`), on its lightly smoothed thrust F and slope F':

- contact: where the first loaded samples extrapolate to zero (the trace's own reading);
- full engagement: where, after the steepest entry slope, F' first falls below
  ``KNEE_FRACTION`` of it (the end of the tip cone's entry ramp); without a clear knee,
  contact + l/f;
- feed stop: one revolution before the loads vanish for good (or the trace's end if it ends
  loaded);
- breakthrough: the start of the first fall between full engagement and the feed stop that
  is steeper than ``FALL_FRACTION`` of the entry slope, lasts over two revolutions (not the
  stop itself) and takes away more than ``MIN_FALL`` of the thrust. The cortex is then
  f × (breakthrough − contact). Without such a fall the trace does not break through: the
  cortex is at least the depth reached, f × (stop − contact), and clogging is never frozen.

Clock (:func:`clock_offset_s`): the Pearson correlation of the rates of change of the
recording and of the trace (both channels when both have torque), smoothed by a Gaussian of
``CLOCK_SMOOTHING_S`` and sampled every ``CLOCK_STEP_S``, over every lag that keeps the trace's
contact ``CONTACT_MARGIN_S`` inside the recording. The rates peak at the edges — contact,
breakthrough, stop — so tare, scale, a drift or a clogging trend change the correlation's value,
not where it peaks. A recording whose own clock runs a few percent fast or slow correlates
poorly everywhere, and its best lag can be spurious: the trace's own clock (lag 0, when it puts
the contact inside the recording) is kept unless another lag correlates better by
``CLOCK_PREFERENCE``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

#: Full engagement: the slope has fallen below this fraction of the steepest entry slope.
KNEE_FRACTION = 0.3
#: A breakthrough fall is steeper than this fraction of the entry slope ...
FALL_FRACTION = 0.2
#: ... and removes at least this fraction of the thrust where it starts.
MIN_FALL = 0.12
#: Grid step of the clock correlation [s].
CLOCK_STEP_S = 0.01
#: Smoothing of the signals whose rates are correlated [s].
CLOCK_SMOOTHING_S = 0.1
#: A placement keeps the trace's contact this far inside the recording [s] (after its start;
#: a full second before its end).
CONTACT_MARGIN_S = 0.3
#: The trace's own clock (lag 0) is kept unless another lag correlates better by this much.
CLOCK_PREFERENCE = 0.1


@dataclass(frozen=True)
class TraceEvents:
    """Times [s] on the trace's clock and the geometry they imply [mm]."""

    contact_s: float
    full_engagement_s: float
    breakthrough_s: float | None
    stop_s: float
    cortex_mm: float | None        #: None when the trace does not break through
    depth_reached_mm: float

    def to_json(self, shift_s: float = 0.0) -> dict:
        """The events moved by ``shift_s`` onto the recording's clock."""
        def at(x):
            return None if x is None or not math.isfinite(x) else round(x + shift_s, 4)
        return {"contact_s": at(self.contact_s), "full_engagement_s": at(self.full_engagement_s),
                "breakthrough_s": at(self.breakthrough_s), "feed_stop_s": at(self.stop_s),
                "cortex_mm": None if self.cortex_mm is None else round(self.cortex_mm, 3),
                "depth_reached_mm": round(self.depth_reached_mm, 3)}


def _smoothed(t: np.ndarray, y: np.ndarray, width_s: float) -> np.ndarray:
    dt = float(np.median(np.diff(t)))
    return ndimage.uniform_filter1d(y, max(int(round(width_s / dt)), 1), mode="nearest")


def trace_events(time_s: np.ndarray, thrust_N: np.ndarray, contact_s: float, stop_s: float,
                 feed_mm_s: float, spindle_rpm: float, cone_mm: float) -> TraceEvents:
    """Events of a noise-free simulated thrust (see the module docstring).

    Parameters
    ----------
    time_s, thrust_N : the trace [s], [N].
    contact_s, stop_s : its contact and feed stop [s] (``stop_s`` infinite if it ends loaded).
    feed_mm_s, spindle_rpm : nominal feed [mm/s] and speed [rpm].
    cone_mm : the drill's tip-cone length l [mm], used when the trace shows no knee.

    Returns
    -------
    TraceEvents

    Examples
    --------
    >>> t = np.linspace(0, 6, 3001)
    >>> F = np.interp(t, [1, 2, 4, 5, 5.05], [0, 20, 20, 4, 0])
    >>> round(trace_events(t, F, 1.0, 5.0, 1.0, 1200, 1.0).cortex_mm, 2)
    3.0
    """
    revolution = 60.0 / spindle_rpm
    F = _smoothed(time_s, thrust_N, min(0.02, revolution / 2))
    slope = np.gradient(F, time_s)
    end = stop_s if math.isfinite(stop_s) else float(time_s[-1])
    entry = (time_s >= contact_s) & (time_s <= min(contact_s + 3 * cone_mm / feed_mm_s, end))
    full = contact_s + cone_mm / feed_mm_s
    entry_slope = float(np.max(slope[entry])) if np.any(entry) else 0.0
    if entry_slope > 0:
        k_max = int(np.flatnonzero(entry)[np.argmax(slope[entry])])
        after = np.flatnonzero((slope[k_max:] < KNEE_FRACTION * entry_slope) & (time_s[k_max:] <= end))
        if after.size:
            full = float(time_s[k_max + after[0]])
    breakthrough = None
    if entry_slope > 0:
        window = (time_s > full) & (time_s < end - 0.5 * revolution)
        falling = window & (slope < -FALL_FRACTION * entry_slope)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], falling.astype(int), [0]])))
        for i, j in zip(edges[::2], edges[1::2]):
            lasting = time_s[j - 1] - time_s[i] >= 2 * revolution
            drop = F[i] - F[j - 1]
            if lasting and F[i] > 0 and drop >= MIN_FALL * F[i]:
                breakthrough = float(time_s[i])
                break
    depth = feed_mm_s * (end - contact_s)
    cortex = None if breakthrough is None else feed_mm_s * (breakthrough - contact_s)
    return TraceEvents(float(contact_s), float(full), breakthrough, float(stop_s), cortex, float(depth))


def clock_offset_s(rec_t: np.ndarray, rec_channels: list[np.ndarray], sim, spindle_rpm: float) -> tuple[float, float]:
    """Lag [s] that best puts the trace ``sim`` (a :class:`~.baseline.TraceSimulation`) on the
    recording's clock, and the correlation there (see the module docstring)."""
    grid = np.arange(rec_t[0], rec_t[-1], CLOCK_STEP_S)
    width = CLOCK_SMOOTHING_S / CLOCK_STEP_S

    def rate(y: np.ndarray) -> np.ndarray:
        return np.gradient(ndimage.gaussian_filter1d(y, width, axis=-1, mode="nearest"), axis=-1)

    recorded = [rate(np.interp(grid, rec_t, _smoothed(rec_t, y, 60.0 / spindle_rpm))) for y in rec_channels]
    lo_span, hi_span = sim.span()
    first, last = grid[0] + CONTACT_MARGIN_S - sim.contact_s, grid[-1] - 1.0 - sim.contact_s
    lags = np.arange(first, last, CLOCK_STEP_S)
    own = first <= 0.0 <= last
    if own:
        lags = np.concatenate([[0.0], lags])
    # the trace covers grid[begin:end] - lag; lags covering as many instants are scored together
    begin = np.searchsorted(grid, lags + lo_span, side="left")
    end = np.searchsorted(grid, lags + hi_span, side="right")
    value = np.full(lags.size, -np.inf)
    for n in np.unique(end - begin):
        if n < 20:
            continue
        group = np.flatnonzero(end - begin == n)
        for chunk in np.array_split(group, max(1, group.size * n // 500_000 + 1)):
            index = begin[chunk, None] + np.arange(n)
            scores = [_correlation(y[index], rate(s))
                      for y, s in zip(recorded, sim.loads(grid[index] - lags[chunk, None])) if s is not None]
            value[chunk] = np.mean(scores, axis=0)
    if not np.isfinite(value).any():
        return 0.0, -math.inf  # no lag leaves enough of the trace to correlate
    k = int(np.argmax(value))
    if own and value[0] >= value[k] - CLOCK_PREFERENCE:
        return 0.0, float(value[0])
    return float(lags[k]), float(value[k])


def _correlation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pearson correlation of each row of ``a`` with the same row of ``b``."""
    a = a - a.mean(axis=-1, keepdims=True)
    b = b - b.mean(axis=-1, keepdims=True)
    norm = np.sqrt(np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b))
    dot = np.einsum("ij,ij->i", a, b)
    return np.divide(dot, norm, out=np.zeros_like(dot), where=norm > 0)
