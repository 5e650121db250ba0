"""Where the drill is surely in air, and what happens there that is not stationary noise.

The noise model (:mod:`.noise`) is fitted where the drill is surely off the bone: more than
:data:`AIR_MARGIN_S` from any load of the aligned simulation (the alignment is known to a few
tenths of a second). What happens there must be stationary noise; anything else is an event the
diagnosis reports (``unexplained``, kind ``air_event``) instead of absorbing it:

- on each channel, the record smoothed by a Gaussian of :data:`SMOOTHING_S`; a **step** on top of
  a straight line (the zero jumped and stayed) when it explains most of what the line leaves and
  stands :data:`EVENT_SIGMAS` robust standard deviations and :data:`EVENT_FRACTION` of the
  channel's peak load (:func:`_step`);
- then compared with a robust straight line through the stretch, a parabola if it is longer than
  1.5 s (three passes of least squares on the samples within 3 robust standard deviations): a
  drift bends gently, an event does not. Samples departing by more than :data:`EVENT_SIGMAS`
  robust standard deviations and :data:`EVENT_FRACTION` of the peak, grouped over gaps under
  0.05 s, are a **load** or a **dip** (a second touch of the bone, a push on the fixture);
- a **burst**: the rms of the record less its running median (0.1 s) in 50 ms windows exceeds
  :data:`BURST_FACTOR` times its median over the stretch (a knock rings at tens of hertz); the
  part above :data:`BURST_EXTENT` times it is left out.

Left out of every fit: a load, dip or burst with :data:`EXCLUSION_S` around it; for a step, the
part of the stretch on the far side of it from the cut, so that the tare is the cut's own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

#: Distance from any simulated load beyond which the drill is surely in air [s].
AIR_MARGIN_S = 0.5
#: Shortest stretch examined [s].
MIN_STRETCH_S = 0.4
SMOOTHING_S = 0.03
EVENT_SIGMAS = 6.0
EVENT_FRACTION = 0.03
BURST_FACTOR = 5.0
BURST_EXTENT = 2.0
#: A step is looked for this far inside a stretch [s], and must explain this share of what a straight
#: line leaves.
STEP_EDGE_S = 0.1
STEP_SHARE = 0.5
BURST_WINDOW_S = 0.05
EXCLUSION_S = 0.2


@dataclass(frozen=True)
class AirEvent:
    """Something in air that is not stationary noise: ``kind`` step, load, dip or burst."""

    kind: str
    channel: str
    start_s: float
    end_s: float
    size: float          #: fraction of the channel's peak load (burst: rms over the stretch's)

    def describe(self, unit: str, peak: float) -> str:
        word = {"thrust_N": "thrust", "torque_Nmm": "torque", "both": "both channels"}[self.channel]
        if self.kind == "step":
            return (f"in air, the zero of the {word} jumps by {100 * self.size:+.1f} % of the peak load at "
                    f"{self.start_s:.2f} s and stays (the amplifier was re-zeroed or a cable moved): the stretch beyond "
                    f"it is left out, so the tare is the cut's own.")
        if self.kind in ("load", "dip"):
            return (f"in air, a {'load' if self.kind == 'load' else 'dip'} of {100 * abs(self.size):.0f} % of the peak "
                    f"({word}) between {self.start_s:.2f} and {self.end_s:.2f} s, when the simulation has the drill off "
                    f"the bone: a second touch of the bone or a push on the fixture. Left out of the fits.")
        return (f"in air, a burst on {word} between {self.start_s:.2f} and {self.end_s:.2f} s, {self.size:.1f} times "
                f"the stretch's usual fluctuation: a knock on the fixture or the specimen. Left out of the fits.")


def stretches(t: np.ndarray, loaded: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [i, j) of samples farther than ``AIR_MARGIN_S`` from any loaded sample and at
    least ``MIN_STRETCH_S`` long."""
    dt = float(np.median(np.diff(t)))
    near = ndimage.binary_dilation(loaded, iterations=max(int(round(AIR_MARGIN_S / dt)), 1)) if loaded.any() else loaded
    edges = np.flatnonzero(np.diff(np.concatenate([[0], (~near).astype(int), [0]])))
    return [(int(i), int(j)) for i, j in zip(edges[::2], edges[1::2]) if t[j - 1] - t[i] >= MIN_STRETCH_S]


def _robust_trend(t: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, float]:
    """Residual of a robust line (a parabola over stretches longer than 1.5 s: a warm-up bends) and
    the residual's robust standard deviation."""
    keep = np.ones(t.size, bool)
    degree = 2 if t[-1] - t[0] > 1.5 else 1
    for _ in range(3):
        coef = np.polyfit(t[keep] - t[0], s[keep], degree)
        e = s - np.polyval(coef, t - t[0])
        sigma = 1.4826 * float(np.median(np.abs(e[keep] - np.median(e[keep])))) or 1e-12
        keep = np.abs(e) < 3 * sigma
        if np.count_nonzero(keep) < 10:
            break
    return e, sigma


def _step_sse(u: np.ndarray, s: np.ndarray, ks: np.ndarray) -> np.ndarray:
    """Sum of squares left by a least-squares line plus a step at each index of ``ks`` (1 from
    there on): what the line leaves, less the part of it along the step's own direction (the
    step with the line projected out), from tail sums instead of one fit per index."""
    n = u.size
    q1 = np.full(n, 1 / np.sqrt(n))
    centred = u - u.mean()
    q2 = centred / (np.linalg.norm(centred) or 1.0)
    r0 = s - q1 * (q1 @ s) - q2 * (q2 @ s)

    def tail(x: np.ndarray) -> np.ndarray:   # Σ_{i ≥ k} x_i at each k of ks
        return np.cumsum(x[::-1])[::-1][ks]

    along_1, along_2 = (n - ks) / np.sqrt(n), tail(q2)
    norm = (n - ks) - along_1 ** 2 - along_2 ** 2
    return float(r0 @ r0) - tail(r0) ** 2 / np.maximum(norm, 1e-300)


def _step(t: np.ndarray, s: np.ndarray, peak: float) -> tuple[float, float, np.ndarray] | None:
    """The strongest step in ``s`` on top of a straight line (time, size, residual of the step
    fit), or None: it must explain most of what the line leaves (``STEP_SHARE``), stand
    ``EVENT_SIGMAS`` robust standard deviations of that residual and ``EVENT_FRACTION`` of the peak.
    The step's index is the one of least sum of squares (:func:`_step_sse`); its fit is then made
    by least squares."""
    edge = max(int(STEP_EDGE_S / float(np.median(np.diff(t)))), 3)
    if t.size < 3 * edge:
        return None
    u = t - t[0]
    line = np.column_stack([np.ones_like(u), u])
    coef, *_ = np.linalg.lstsq(line, s, rcond=None)
    base = float(np.sum((s - line @ coef) ** 2))
    ks = np.arange(edge, t.size - edge, max(edge // 4, 1))
    k = int(ks[np.argmin(_step_sse(u, s, ks))])
    A = np.column_stack([line, (np.arange(t.size) >= k).astype(float)])
    c, *_ = np.linalg.lstsq(A, s, rcond=None)
    r = s - A @ c
    sse, size = float(r @ r), float(c[2])
    sigma = 1.4826 * float(np.median(np.abs(r - np.median(r)))) or 1e-12
    if base - sse < STEP_SHARE * base or abs(size) < EVENT_SIGMAS * sigma or abs(size) < EVENT_FRACTION * peak:
        return None
    return float(t[k]), size, r


def find(t: np.ndarray, channels: dict, loaded: np.ndarray, peaks: dict) -> tuple[list[AirEvent], np.ndarray, np.ndarray]:
    """Events in the air stretches, the samples to leave out, and the samples surely in air.

    ``channels`` maps names to raw arrays, ``loaded`` marks samples where the aligned simulation
    has load, ``peaks`` each channel's simulated peak."""
    dt = float(np.median(np.diff(t)))
    excluded = np.zeros(t.size, bool)
    air = np.zeros(t.size, bool)
    events: list[AirEvent] = []
    loaded_idx = np.flatnonzero(loaded)
    for i, j in stretches(t, loaded):
        air[i:j] = True
        before_cut = bool(loaded_idx.size) and j <= loaded_idx[0] + 1
        tt = t[i:j]
        for name, x in channels.items():
            if x is None:
                continue
            seg = x[i:j]
            s = ndimage.gaussian_filter1d(seg, max(SMOOTHING_S / dt, 0.5), mode="nearest")
            step = _step(tt, s, peaks[name])
            if step is not None:
                at, size, _ = step
                events.append(AirEvent("step", name, at, at + 0.1, size / peaks[name]))
                side = (tt < at) if before_cut else (tt >= at)   # the side away from the cut
                excluded[i:j] |= side
                s = np.where(tt < at, s + size, s) if not before_cut else np.where(tt >= at, s - size, s)
            e, sigma = _robust_trend(tt, s)
            flagged = (np.abs(e) > EVENT_SIGMAS * sigma) & (np.abs(e) > EVENT_FRACTION * peaks[name])
            if flagged.any():
                flagged = ndimage.binary_closing(flagged, iterations=max(int(0.05 / dt), 1)) & (np.abs(e) > 0)
            edges = np.flatnonzero(np.diff(np.concatenate([[0], flagged.astype(int), [0]])))
            for a, b in zip(edges[::2], edges[1::2]):
                if tt[b - 1] - tt[a] < 0.03:
                    continue
                size = float(np.mean(e[a:b])) / peaks[name]
                events.append(AirEvent("load" if size > 0 else "dip", name, float(tt[a]), float(tt[b - 1]), size))
                excluded |= (t >= tt[a] - EXCLUSION_S) & (t <= tt[b - 1] + EXCLUSION_S)
            _bursts(t, tt, seg, name, dt, events, excluded)
    return _merged(events), excluded, air & ~excluded


def _bursts(t, tt, seg, name, dt, events, excluded) -> None:
    """High-frequency energy in short windows: a run whose rms passes ``BURST_FACTOR`` times the
    stretch's median, extended while it stays above ``BURST_EXTENT`` times it (a ringing decays);
    left out, and reported unless it is the ringing of a load already found."""
    width = max(int(round(BURST_WINDOW_S / dt)), 4)
    if seg.size < 4 * width:
        return
    hp = seg - ndimage.median_filter(seg, size=max(int(0.1 / dt), 3), mode="nearest")
    rms = np.sqrt(ndimage.uniform_filter1d(hp ** 2, width, mode="nearest"))
    level = float(np.median(rms)) or 1e-12
    loud_edges = np.flatnonzero(np.diff(np.concatenate([[0], (rms > BURST_FACTOR * level).astype(int), [0]])))
    for a, b in zip(loud_edges[::2], loud_edges[1::2]):
        while a > 0 and rms[a - 1] > BURST_EXTENT * level:
            a -= 1
        while b < rms.size and rms[b] > BURST_EXTENT * level:
            b += 1
        excluded |= (t >= tt[a] - EXCLUSION_S) & (t <= tt[b - 1] + EXCLUSION_S)
        if not any(ev.channel == name and ev.start_s - 0.2 <= tt[a] <= ev.end_s + 0.2 for ev in events):
            events.append(AirEvent("burst", name, float(tt[a]), float(tt[b - 1]), float(rms[a:b].max() / level)))


def _merged(events: list[AirEvent]) -> list[AirEvent]:
    """One event for both channels where the two channels' events of one kind overlap."""
    out: list[AirEvent] = []
    for ev in sorted(events, key=lambda e: e.start_s):
        twin = next((o for o in out if o.kind == ev.kind and o.channel != ev.channel and o.channel != "both"
                     and ev.start_s <= o.end_s + 0.1 and o.start_s <= ev.end_s + 0.1), None)
        if twin is None:
            out.append(ev)
        else:
            out[out.index(twin)] = AirEvent(ev.kind, "both", min(twin.start_s, ev.start_s), max(twin.end_s, ev.end_s),
                                            twin.size if abs(twin.size) >= abs(ev.size) else ev.size)
    return out
