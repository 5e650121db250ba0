"""Channel sanity: is each recorded channel what its column says, compared with the simulation?

A wrong sign, swapped columns, a unit other than the column's or a clipped converter are not
physics, and a fitted scale must not hide them (a scale of −0.98 is a polarity, not a 202 %
error). They are checked before anything is fitted, reported as findings (the ``unexplained``
list, with ``kind`` below), and corrected so that the diagnosis can go on:

- ``polarity``: the channel's rate of change correlates *negatively* with the simulation's at the
  best clock lag (:func:`.timing.clock_offset_s` tries both signs of every channel);
  or, against a load model, the thrust's excursion from its baseline is downward. The channel
  is negated.
Scales and pairings are read from level ratios (:func:`_level_ratio`): the median of the channel
(less a straight zero through its unloaded instants) where the simulation is loaded, over the
simulation's median there. Missing physics moves such a ratio by tens of percent, a unit mistake
by a factor:

- ``swapped_channels``: with both channels, the crossed ratios (recorded thrust over simulated
  torque and the reverse) are both within :data:`SWAP_TOLERANCE` of 1 or a unit factor, and nearer
  to them by :data:`SWAP_MARGIN` than the ratios as labelled, or the labelled ratios read
  plausibly too. Unless the crossed ratios are clearly nearer and, as labelled, a channel is off
  by more than :data:`SCALE_LIMIT` (a fault either way), the entry must confirm it
  (:func:`_entry_crossed`): as the cone engages, the torque grows with the moment of the engaged
  lips and the thrust with their length, so torque over thrust rises with depth. That ratio is
  the same whatever the feed does (a pulsing or faltering feed scales both channels alike and the
  depth stays monotone), where the channels' own shapes are not. Recorded columns whose ratio
  falls through the entry while the simulation's rises are swapped. The channels are swapped back.
- ``unit_scale``: a channel's ratio is off by more than :data:`SCALE_LIMIT` and within
  :data:`UNIT_TOLERANCE` of a unit factor (:data:`UNIT_FACTORS`: kN, daN, lbf, kgf, N·m, lbf·in
  written under another unit's name). The channel is rescaled by the factor. ``channel_scale``:
  off by more than that and near no unit factor; rescaled by the ratio, and the report says so.
- ``clipping``: a channel's extreme value is held for :data:`MIN_CLIPPED` samples or more, in runs,
  and far more often than the next level (a converter at the end of its range piles samples up
  there; a quantised signal's natural extreme is a thin tail). Those samples are left out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage, stats

from femstudy.recordings.reader import Recording

#: Written value / true value of the unit mistakes recognised, with their names.
UNIT_FACTORS = ((1e-3, "a thousandth of the load (kN written as N, or N·m as N·mm)"),
                (1e3, "a thousand times the load (N written as kN, or N·mm as N·m)"),
                (0.1, "a tenth of the load (daN written as N)"), (10.0, "ten times the load"),
                (1 / 4.44822, "lbf written as N"), (4.44822, "N written as lbf"),
                (1 / 9.80665, "kgf written as N"), (9.80665, "N written as kgf"),
                (1 / 112.985, "lbf·in written as N·mm"), (112.985, "N·mm written as lbf·in"),
                (1000 / 112.985, "lbf·in written as N·m"), (112.985 / 1000, "N·m written as lbf·in"))
#: Where the simulation exceeds this fraction of its peak, in the first ``EARLY`` of that span (before
#: clogging has grown or softening set in), its level is compared with the channel's.
LOADED = 0.2
EARLY = 0.4
#: A channel reading more than this factor off the simulation is a finding (missing physics moves
#: the level by tens of percent: a clogging rise of 70 % by breakthrough moves its median less).
SCALE_LIMIT = 3.0
#: A unit factor is recognised within this factor.
UNIT_TOLERANCE = 1.4
#: Swapped columns: both crossed ratios within this factor of 1 or a unit factor, and nearer by
#: this factor (in the sum of log distances) than the labelled ones.
SWAP_TOLERANCE = 1.3
SWAP_MARGIN = 1.5
#: When both pairings read plausibly (thrust and torque of similar size, or unit factors on both
#: sides), the entry decides: the rank correlation of torque over thrust with time through the
#: entry, where both channels carry at least ``ENTRY_LOADED`` of their entry peak, must pass this
#: with one sign in the simulation and with the other in the recording.
RATIO_TREND = 0.6
ENTRY_LOADED = 0.15
#: Least absolute rate correlation at which a negative sign is read as a polarity.
MIN_CORRELATION = 0.3
#: A channel's extreme value held this many samples, some of them in a run of ``MIN_RUN``, is a
#: clipped converter.
MIN_CLIPPED = 20
MIN_RUN = 5
#: ... and piled up: held at least this many times as often as the next level (a quantised signal's
#: natural extreme is a thin tail).
PILE_UP = 3

NAMES = {"thrust_N": "thrust", "torque_Nmm": "torque"}


@dataclass(frozen=True)
class Finding:
    """A channel fault: kind, channel (``thrust_N``, ``torque_Nmm`` or ``both``), the factor the
    channel was multiplied by to correct it, a sentence, and the interval it concerns [s]."""

    kind: str
    channel: str
    factor: float
    description: str
    start_s: float
    end_s: float

    def to_json(self) -> dict:
        return {"start_s": round(self.start_s, 3), "end_s": round(self.end_s, 3), "channel": self.channel,
                "kind": self.kind, "description": self.description,
                "evidence": {"correction_factor": float(f"{self.factor:.6g}")}}


def running_mean(t: np.ndarray, y: np.ndarray, width_s: float) -> np.ndarray:
    """``y`` averaged over a window of ``width_s`` [s] (at least one sample), edges extended."""
    dt = float(np.median(np.diff(t)))
    return ndimage.uniform_filter1d(y, max(int(round(width_s / dt)), 1), mode="nearest")


def polarity_from_excursion(rec: Recording) -> list[Finding]:
    """Against a load model (no trace to correlate with): the thrust's excursion from its median is
    downward."""
    x = running_mean(rec.time_s, rec.thrust_N, 0.05)
    low, mid, high = np.percentile(x, [0.5, 50, 99.5])
    if mid - low > 3 * (high - mid) and mid - low > 0:
        return [Finding("polarity", "thrust_N", -1.0, "the thrust is written with the opposite sign (its load is "
                        "negative): the diagnosis uses the negated channel.", float(rec.time_s[0]),
                        float(rec.time_s[-1]))]
    return []


def _level_ratio(t: np.ndarray, x: np.ndarray, sim: np.ndarray) -> float:
    """The recorded channel's level over the simulated one's where the simulation is loaded (above
    ``LOADED`` of its peak, in the first ``EARLY`` of that span): median of (x − zero) over median
    of the simulation, the zero a straight line through the instants where the simulation is
    unloaded (a drifting zero must not pass for a scale). Missing physics moves this by tens of
    percent, a unit mistake by a factor."""
    peak = max(float(np.max(np.abs(sim))), 1e-12)
    loaded = np.abs(sim) > LOADED * peak
    if np.count_nonzero(loaded) < 10:
        return 1.0
    first, last = t[loaded][0], t[loaded][-1]
    early = loaded & (t <= first + EARLY * (last - first))
    if np.count_nonzero(early) >= 10:
        loaded = early
    level = float(np.median(sim[loaded]))
    return float(np.median(_from_zero(t, x, sim)[loaded])) / level if level != 0 else 1.0


def _from_zero(t: np.ndarray, x: np.ndarray, sim: np.ndarray) -> np.ndarray:
    """``x`` less a straight zero through the instants where ``sim`` is below 1 % of its peak (x
    itself with fewer than 10 of them)."""
    free = np.abs(sim) < 0.01 * max(float(np.max(np.abs(sim))), 1e-12)
    return x - np.polyval(np.polyfit(t[free], x[free], 1), t) if np.count_nonzero(free) >= 10 else x


def _ratio_trend(t: np.ndarray, thrust: np.ndarray, torque: np.ndarray) -> float | None:
    """Spearman's rank correlation of torque/thrust with time over the instants where both carry
    at least ``ENTRY_LOADED`` of their peak there; None with fewer than 10 such instants."""
    both = (thrust > ENTRY_LOADED * thrust.max()) & (torque > ENTRY_LOADED * torque.max())
    if np.count_nonzero(both) < 10 or thrust.max() <= 0 or torque.max() <= 0:
        return None
    return float(stats.spearmanr(t[both], torque[both] / thrust[both]).statistic)


def _entry_crossed(t: np.ndarray, smooth: dict, F_sim: np.ndarray, T_sim: np.ndarray, ramp: np.ndarray) -> bool:
    """Whether the recorded torque/thrust runs against the simulation's through the entry
    (``ramp``): one rises (``RATIO_TREND``) while the other falls. The recorded channels are taken
    from their zero (a straight line through the instants the simulation has unloaded)."""
    if np.count_nonzero(ramp) < 20:
        return False
    recorded = [_from_zero(t, smooth[c], sim)[ramp] for c, sim in (("thrust_N", F_sim), ("torque_Nmm", T_sim))]
    simulated, seen = _ratio_trend(t[ramp], F_sim[ramp], T_sim[ramp]), _ratio_trend(t[ramp], *recorded)
    if simulated is None or seen is None:
        return False
    return abs(simulated) >= RATIO_TREND and abs(seen) >= RATIO_TREND and simulated * seen < 0


def _distance(ratio: float, with_one: bool = True) -> tuple[float, tuple[float, str] | None]:
    """|ln| of ``ratio`` to the nearest of 1 (if ``with_one``) and the unit factors, and that factor
    (None for 1)."""
    if ratio <= 0:
        return math.inf, None
    options = ([(1.0, "")] if with_one else []) + list(UNIT_FACTORS)
    best = min(options, key=lambda f: abs(math.log(ratio / f[0])))
    return abs(math.log(ratio / best[0])), (None if best[0] == 1.0 else best)


def check(rec: Recording, sim, correlations: tuple[float, ...]) -> tuple[Recording, list[Finding]]:
    """The recording with its channels corrected, and the findings (see the module docstring).
    ``sim`` is the trace on the recording's clock; ``correlations`` the channels' rate correlations
    with it at that lag."""
    t = rec.time_s
    span = (float(t[0]), float(t[-1]))
    findings: list[Finding] = []
    channels = {"thrust_N": rec.thrust_N, "torque_Nmm": rec.torque_Nmm}
    names = [c for c in ("thrust_N", "torque_Nmm") if channels[c] is not None][:len(correlations)]
    for c, rho in zip(names, correlations):
        if rho < 0 and abs(rho) >= MIN_CORRELATION:
            channels[c] = -channels[c]
            findings.append(Finding("polarity", c, -1.0, f"the {NAMES[c]} is written with the opposite sign: its "
                                    f"rate of change correlates with the simulation's at r = {rho:.2f}. The "
                                    f"diagnosis uses the negated channel.", *span))
    lo, hi = sim.span()
    inside = (t >= lo) & (t <= hi)
    if np.count_nonzero(inside) < 20:
        return replace(rec, thrust_N=channels["thrust_N"], torque_Nmm=channels["torque_Nmm"]), findings
    F_sim, T_sim = sim.loads(t[inside])
    sims = {"thrust_N": F_sim, "torque_Nmm": T_sim}
    revolution = 60.0 / rec.spindle_rpm
    smooth = {c: running_mean(t, channels[c], revolution)[inside] for c in names}
    tt = t[inside]
    if len(names) == 2 and T_sim is not None:
        straight = (_level_ratio(tt, smooth["thrust_N"], F_sim), _level_ratio(tt, smooth["torque_Nmm"], T_sim))
        crossed = (_level_ratio(tt, smooth["thrust_N"], T_sim), _level_ratio(tt, smooth["torque_Nmm"], F_sim))
        d_straight = sum(_distance(r)[0] for r in straight)
        d_crossed = sum(_distance(r)[0] for r in crossed)
        by_level = d_crossed < d_straight - math.log(SWAP_MARGIN)
        swapped = d_crossed < 2 * math.log(SWAP_TOLERANCE) and (by_level or d_straight < 2 * math.log(SWAP_TOLERANCE))
        fault_as_labelled = any(r <= 0 or abs(math.log(r)) > math.log(SCALE_LIMIT) for r in straight)
        if swapped and not (by_level and fault_as_labelled):
            # both pairings read plausibly, or the labelled one needs no fault: the entry decides
            entry = rec.drill.cone_length_mm / rec.feed_mm_s
            ramp = (tt >= sim.contact_s - 0.2 * entry) & (tt <= sim.contact_s + 1.3 * entry)
            swapped = _entry_crossed(tt, smooth, F_sim, T_sim, ramp)
        if swapped:
            channels["thrust_N"], channels["torque_Nmm"] = channels["torque_Nmm"], channels["thrust_N"]
            smooth["thrust_N"], smooth["torque_Nmm"] = smooth["torque_Nmm"], smooth["thrust_N"]
            findings.append(Finding("swapped_channels", "both", 1.0, "the thrust and torque columns are swapped: each "
                                    f"reads like the other simulated channel (level ratios {crossed[0]:.3g} and "
                                    f"{crossed[1]:.3g} crossed, {straight[0]:.3g} and {straight[1]:.3g} as labelled). "
                                    f"The diagnosis swaps them back.", *span))
    for c in names:
        if sims[c] is None:
            continue
        ratio = _level_ratio(tt, smooth[c], sims[c])
        if ratio <= 0 or abs(math.log(ratio)) <= math.log(SCALE_LIMIT):
            continue
        distance, unit = _distance(ratio, with_one=False)
        if distance < math.log(UNIT_TOLERANCE):
            factor = 1.0 / unit[0]
            findings.append(Finding("unit_scale", c, factor, f"the {NAMES[c]} column holds {unit[1]}: it reads "
                                    f"{ratio:.4g} times the simulation. The diagnosis rescales it by {factor:.4g}.",
                                    *span))
        else:
            factor = 1.0 / ratio
            findings.append(Finding("channel_scale", c, factor, f"the {NAMES[c]} reads {ratio:.3g} times the "
                                    f"simulation, which no unit mistake explains (a wrong calibration, gain or "
                                    f"simulation). The diagnosis rescales it by {factor:.3g}; read what follows "
                                    f"with that in mind.", *span))
        channels[c] = channels[c] * factor
    return replace(rec, thrust_N=channels["thrust_N"], torque_Nmm=channels["torque_Nmm"]), findings


def clipped(rec: Recording) -> tuple[np.ndarray, list[Finding]]:
    """Samples held at a channel's extreme value (a clipped converter), and the findings."""
    t = rec.time_s
    mask = np.zeros(t.size, bool)
    findings = []
    for c, x in (("thrust_N", rec.thrust_N), ("torque_Nmm", rec.torque_Nmm)):
        if x is None:
            continue
        levels, counts = np.unique(x, return_counts=True)
        for extreme, held_count, next_count in ((levels[-1], counts[-1], counts[-2] if levels.size > 1 else 0),
                                                (levels[0], counts[0], counts[1] if levels.size > 1 else 0)):
            held = x == extreme
            edges = np.flatnonzero(np.diff(np.concatenate([[0], held.astype(int), [0]])))
            longest = int(np.max(edges[1::2] - edges[::2])) if edges.size else 0
            if (MIN_CLIPPED <= held_count < 0.5 * x.size and longest >= MIN_RUN
                    and held_count >= PILE_UP * next_count):
                where = np.flatnonzero(held)
                mask |= held
                findings.append(Finding("clipping", c, 1.0, f"the {NAMES[c]} is clipped at {extreme:.4g}: "
                                        f"{where.size} samples between {t[where[0]]:.2f} and {t[where[-1]]:.2f} s sit at "
                                        f"the converter's limit and are left out.", float(t[where[0]]),
                                        float(t[where[-1]])))
    return mask, findings
