"""Timing and geometry from the simulation: its events, and its clock against the recording's.

A simulated trace is noise-free and says where the cut is. So when one is given, the
diagnosis takes contact, full engagement, breakthrough and the cortex thickness from it, and
places it on the recording's clock by correlation, instead of detecting the cut in a noisy
recording (which can fail: a drifting low-feed recording, or clogging that keeps the loads
high until the drill stops, which looks like a retraction).

Events of a trace (:func:`trace_events`), on its lightly smoothed thrust F and slope F':

- contact: where the first loaded samples extrapolate to zero (the trace's own reading);
- full engagement: where, between ``KNEE_WINDOW`` times l/f after contact, F' first falls below
  ``KNEE_FRACTION`` of the ramp's median slope (the end of the tip cone's entry ramp; a chisel
  edge's step at contact does not count); without such a knee, contact + l/f;
- feed stop: one revolution before the loads vanish for good (or the trace's end if it ends
  loaded);
- breakthrough: the start of the first fall between full engagement and the feed stop that
  is steeper than ``FALL_FRACTION`` of the slope of the cone leaving the cortex (the thrust at
  full engagement over l/f), lasts over two revolutions and ``MIN_FALL_DURATION`` of l/f (the fall
  after the feed stops lasts a revolution or a few; at 1 mm/s and 800 rpm the exit takes over a
  second, some fifteen revolutions) and takes away more than ``MIN_FALL`` of the thrust. A steep
  entry (a chisel edge's step at contact) does not set the scale. The cortex is then
  f × (breakthrough − contact). Without such a fall the trace does not break through: the
  cortex is at least the depth reached, f × (stop − contact), and clogging is never frozen.

Clock (:func:`clock_offset_s`): the Pearson correlation of the rates of change of the
recording and of the trace (both channels when both have torque), smoothed by a Gaussian of
``CLOCK_SMOOTHING_S`` and sampled every ``CLOCK_STEP_S``, over every lag that keeps the trace's
contact ``CONTACT_MARGIN_S`` inside the recording. The rates peak at the edges — contact,
breakthrough, stop — so tare, scale, a drift or a clogging trend change the correlation's value,
not where it peaks. A channel written upside down is placed too (a rate alone cannot tell an
inverted channel from the trace's entry put on the recording's exit): its sign is that of its
strongest level correlation, where the plateau of the cut meets the recording's. A sensor drift
larger than the load can turn that over, so for a trace with both edges the rates around each
edge overrule the levels when they clearly show another placement: at a mirror lag one of the
trace's edges lies in air. A recording whose own clock runs a few percent fast or slow
correlates poorly everywhere, and its best lag can be spurious: the trace's own clock (lag 0,
when it puts the contact inside the recording) is kept unless another lag correlates better by
``CLOCK_PREFERENCE``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, signal

from femstudy.diagnosis.sanity import MIN_CORRELATION, running_mean

#: The trace is smoothed over this fraction of l/f (at least 20 ms or half a revolution) for its
#: events, and a fall may pause this long: a simulation's loads can move in steps (lip elements,
#: a mesh) that stall a slow fall for tens of milliseconds.
SMOOTHING_OF_ENTRY = 0.08
#: Full engagement: the slope has fallen below this fraction of the ramp's (its median over the
#: middle of the cone's entry time l/f), looked for between these multiples of l/f after contact.
KNEE_FRACTION = 0.3
KNEE_WINDOW = (0.6, 1.5)
#: A breakthrough fall is steeper than this fraction of the geometric exit slope F·f/l (the cone
#: leaving the cortex takes l/f) ...
FALL_FRACTION = 0.2
#: ... removes at least this fraction of the thrust where it starts ...
MIN_FALL = 0.12
#: ... and lasts at least two revolutions and this fraction of l/f (the fall after the feed stops
#: lasts a revolution or a few: at slow feed, l/f is far longer).
MIN_FALL_DURATION = 0.3
#: Grid step of the clock correlation [s].
CLOCK_STEP_S = 0.01
#: Smoothing of the signals whose rates are correlated [s].
CLOCK_SMOOTHING_S = 0.1
#: A placement keeps the trace's contact this far inside the recording [s] (after its start;
#: a full second before its end).
CONTACT_MARGIN_S = 0.3
#: A trace's edge (entry or exit) is where its thrust's rate exceeds ``EDGE_FRACTION`` of the
#: largest on its side of the cut's middle, widened by ``EDGE_MARGIN_S`` [s] (twice the smoothing).
EDGE_FRACTION = 0.2
EDGE_MARGIN_S = 0.2
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
    >>> round(trace_events(t, F, 1.0, 5.0, 1.0, 1200, 1.0).cortex_mm, 1)
    3.0
    """
    revolution = 60.0 / spindle_rpm
    entry_s = cone_mm / feed_mm_s
    F = running_mean(time_s, thrust_N, max(min(0.02, revolution / 2), SMOOTHING_OF_ENTRY * entry_s))
    slope = np.gradient(F, time_s)
    end = stop_s if math.isfinite(stop_s) else float(time_s[-1])
    full = contact_s + entry_s
    ramp = (time_s >= contact_s + 0.2 * entry_s) & (time_s <= contact_s + 0.8 * entry_s)
    ramp_slope = float(np.median(slope[ramp])) if np.count_nonzero(ramp) >= 3 else 0.0
    if ramp_slope > 0:
        later = np.flatnonzero((time_s >= contact_s + KNEE_WINDOW[0] * entry_s)
                               & (time_s <= min(contact_s + KNEE_WINDOW[1] * entry_s, end))
                               & (slope < KNEE_FRACTION * ramp_slope))
        if later.size:
            full = float(time_s[later[0]])
    breakthrough = None
    exit_s = cone_mm / feed_mm_s
    engaged = float(np.interp(full, time_s, F))
    if engaged > 0:
        window = (time_s > full) & (time_s < end - 0.5 * revolution)
        falling = window & (slope < -FALL_FRACTION * engaged / exit_s)
        step = float(np.median(np.diff(time_s)))
        falling = ndimage.binary_closing(falling, iterations=max(int(SMOOTHING_OF_ENTRY * exit_s / step), 1)) & window
        edges = np.flatnonzero(np.diff(np.concatenate([[0], falling.astype(int), [0]])))
        for i, j in zip(edges[::2], edges[1::2]):
            lasting = time_s[j - 1] - time_s[i] >= max(2 * revolution, MIN_FALL_DURATION * exit_s)
            drop = F[i] - F[j - 1]
            if lasting and F[i] > 0 and drop >= MIN_FALL * F[i]:
                breakthrough = float(time_s[i])
                break
    depth = feed_mm_s * (end - contact_s)
    cortex = None if breakthrough is None else feed_mm_s * (breakthrough - contact_s)
    return TraceEvents(float(contact_s), float(full), breakthrough, float(stop_s), cortex, float(depth))


def clock_offset_s(rec_t: np.ndarray, rec_channels: list[np.ndarray], sim, spindle_rpm: float
                   ) -> tuple[float, float, tuple[float, ...]]:
    """Lag [s] that best puts the trace ``sim`` (a :class:`~.baseline.TraceSimulation`) on the
    recording's clock, the mean correlation there, and each channel's rate correlation (its sign
    says whether the channel is written with the trace's polarity; see the module docstring).

    The rates place the lag precisely but cannot tell a channel written upside down from a wrong
    lag: the entry's rise and the exit's fall are edges of similar size, so the trace's entry put
    on the recording's exit correlates as strongly (often more, when clogging made the exit the
    larger edge), with the opposite sign. The levels can: the plateau of the cut correlates with
    the recording's plateau far more than with anything at a mirror lag. So each channel's sign
    is that of its level correlation of largest size over all lags, and the lag maximises the
    mean rate correlation taken with those signs.

    A sensor drift larger than the load correlates with a plateau put anywhere and can turn the
    levels' signs over. A trace with both edges (load-free before contact and after the stop)
    has a second witness: at its right placement both edges meet edges of the recording, at a
    mirror one an edge lies in air. So every choice of signs also takes its best lag, and is
    scored by its weaker edge (the signed rate correlation around the trace's entry and around
    its exit); the best of them overrules the levels' choice when its weaker edge correlates at
    least at :data:`~.sanity.MIN_CORRELATION` and better than the levels' choice by
    ``CLOCK_PREFERENCE``, and its mean rate correlation is not worse by more than that: the
    ambiguity is between placements that correlate about as well. A feed or clock off by some
    percent blurs one edge at the right placement; there the levels' choice stands."""
    grid = np.arange(rec_t[0], rec_t[-1], CLOCK_STEP_S)
    width = CLOCK_SMOOTHING_S / CLOCK_STEP_S

    def level(y: np.ndarray) -> np.ndarray:
        return gaussian_rows(y, width)

    levels = [level(np.interp(grid, rec_t, running_mean(rec_t, y, 60.0 / spindle_rpm))) for y in rec_channels]
    recorded = [np.gradient(y) for y in levels]
    lo_span, hi_span = sim.span()
    first, last = grid[0] + CONTACT_MARGIN_S - sim.contact_s, grid[-1] - 1.0 - sim.contact_s
    lags = np.arange(first, last, CLOCK_STEP_S)
    own = first <= 0.0 <= last
    if own:
        lags = np.concatenate([[0.0], lags])
    # the trace covers grid[begin:end] - lag; lags covering as many instants are scored together
    begin = np.searchsorted(grid, lags + lo_span, side="left")
    end = np.searchsorted(grid, lags + hi_span, side="right")
    n_channels = min(sum(1 for s in sim.loads(grid[:1]) if s is not None), len(recorded))

    def trace_levels(rows: np.ndarray, chunk: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """The placed trace's smoothed levels and rates on ``grid[rows]`` (lags ``lags[chunk]``)."""
        loads = [level(s) for s in sim.loads(grid[rows] - lags[chunk, None]) if s is not None][:n_channels]
        return [(s, np.gradient(s, axis=-1)) for s in loads]

    def weaker_edge(k: int, signs: np.ndarray) -> float:
        """The weaker of the signed rate correlations around the placed trace's two edges (its
        entry and its exit: where its thrust's rate exceeds ``EDGE_FRACTION`` of the largest on
        that side of the cut's middle, widened by ``EDGE_MARGIN_S``); 0 for an edge the recording
        does not hold."""
        rows = np.arange(begin[k], end[k])
        t = grid[rows]
        rates = [rate[0] for _, rate in trace_levels(rows[None], np.array([k]))]
        steep = np.abs(rates[0])
        middle = (sim.contact_s + sim.stop_s) / 2 + lags[k]
        scores = []
        for side in (t < middle, t >= middle):
            edge = side & (steep > EDGE_FRACTION * np.max(steep, where=side, initial=0.0))
            if not edge.any():
                return 0.0
            window = (t >= t[edge].min() - EDGE_MARGIN_S) & (t <= t[edge].max() + EDGE_MARGIN_S)
            if np.count_nonzero(window) < 20:
                return 0.0
            scores.append(np.mean([sign * _correlation(recorded[c][rows[window]][None], rate[window][None])[0]
                                   for c, (sign, rate) in enumerate(zip(signs, rates))]))
        return min(scores)

    by_rate = np.full((n_channels, lags.size), np.nan)
    by_level = np.zeros((n_channels, lags.size))
    for n in np.unique(end - begin):
        if n < 20:
            continue
        group = np.flatnonzero(end - begin == n)
        for chunk in np.array_split(group, max(1, group.size * n // 500_000 + 1)):
            index = begin[chunk, None] + np.arange(n)
            for c, (smooth, rate) in enumerate(trace_levels(index, chunk)):
                by_rate[c, chunk] = _correlation(recorded[c][index], rate)
                by_level[c, chunk] = _correlation(levels[c][index], smooth)
    if not np.isfinite(by_rate).any():
        return 0.0, -math.inf, tuple(1.0 for _ in range(n_channels))  # too little overlap anywhere
    complete = np.isfinite(by_rate).all(axis=0)

    def best_lag(signs: np.ndarray) -> tuple[int, float]:
        value = np.where(complete, np.mean(signs[:, None] * np.nan_to_num(by_rate), axis=0), -np.inf)
        k = int(np.argmax(value))
        if own and value[0] >= value[k] - CLOCK_PREFERENCE:
            k = 0
        return k, float(value[k])

    strongest = np.argmax(np.abs(by_level), axis=1)
    by_levels = np.where(by_level[np.arange(n_channels), strongest] < 0, -1.0, 1.0)
    k, value = best_lag(by_levels)
    if sim.zero_before and sim.zero_after:   # both edges: their rates can overrule the levels
        placements = {}
        for signs in itertools.product((1.0, -1.0), repeat=n_channels):
            k_signs, value_signs = best_lag(np.array(signs))
            placements[signs] = (weaker_edge(k_signs, np.array(signs)), k_signs, value_signs)
        edge, k_edge, value_edge = max(placements.values())
        levels_edge = placements[tuple(float(s) for s in by_levels)][0]   # the levels' own choice
        clearer = edge >= MIN_CORRELATION and edge >= levels_edge + CLOCK_PREFERENCE
        if clearer and value_edge >= value - CLOCK_PREFERENCE:
            k, value = k_edge, value_edge
    return float(lags[k]), value, tuple(float(v) for v in by_rate[:, k])


def gaussian_rows(y: np.ndarray, sigma: float) -> np.ndarray:
    """Each row of ``y`` smoothed by a Gaussian of ``sigma`` samples, edges extended by their
    nearest value: :func:`scipy.ndimage.gaussian_filter1d` (``mode="nearest"``, the kernel to
    4 σ) to round-off, as one FFT convolution of all rows, twice as fast on the clock search's
    thousands of placed traces."""
    if y.shape[-1] == 0:
        return y.astype(float)
    radius = int(4 * sigma + 0.5)
    x = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 * (x / sigma) ** 2)
    padded = np.pad(y, [(0, 0)] * (y.ndim - 1) + [(radius, radius)], mode="edge")
    return signal.fftconvolve(padded, (kernel / kernel.sum()).reshape((1,) * (y.ndim - 1) + (-1,)), mode="valid",
                              axes=-1)


def _correlation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pearson correlation of each row of ``a`` with the same row of ``b``."""
    a = a - a.mean(axis=-1, keepdims=True)
    b = b - b.mean(axis=-1, keepdims=True)
    norm = np.sqrt(np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b))
    dot = np.einsum("ij,ij->i", a, b)
    return np.divide(dot, norm, out=np.zeros_like(dot), where=norm > 0)
