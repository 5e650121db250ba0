"""What the best catalogue model leaves: located, characterised, reported as "unexplained".

The residual r_c of each channel is searched for structure of generic shapes, each a few
columns on the modelled load L_c(t) (the fitted simulation with its mechanisms, smoothed like
the data), fitted by generalised least squares with the recording's noise model:

=================  =================================================  ======================
shape (``kind``)   columns                                            scanned
=================  =================================================  ======================
step               L·H(t − t0): the loads change by a fraction at t0    t0 in the cut
bump               L·hann((t − t1)/w): a local excess or deficit; or  t1; w ∈ 0.5–3 s, or
                   L·layer(t): the share of the lips inside a layer   d ∈ 0.25–2 mm
                   of thickness d entered by the tip at t1, weighted
                   uniformly along the lip (thrust) or by radius
                   (torque, so it lags the thrust); the layer may end
                   after the cut if half its fall comes before the
                   cut ends and the tip leaves the cortex
oscillation        L·sin 2πft, L·cos 2πft in the cut                  f ∈ 0.2–4 Hz (≥ 1.5
                                                                      periods in the cut)
timing             [L(t_c + (1 + ε)(t − t_c − δ)) − L] + a·L: the     ε ∈ ±1–20 %,
                   events after contact run early or late (the         δ ∈ ±0.3 s
                   re-timing enters whole) and the loads scale by a
                   (a feed or clock other than stated); both channels
load_power         L²/max L, L: an excess growing with the load        —
=================  =================================================  ======================

Each shape is fitted to both channels (own amplitudes) or to one alone; the variant with the
larger gain Δχ² − k ln n − 2 ln m wins (k its columns and scanned parameters, m the candidates
scanned: the best of m tries on pure noise gains about 2 ln m). A shape carried by
the torque or the thrust alone is reported as ``torque_only`` / ``thrust_only`` (a step or
bump) or as a one-channel oscillation.

Two uses:

- **Characterising** (:func:`characterise`): on the final residual, the best shape is kept
  when its gain is at least ``MIN_GAIN`` and its size (the fraction of the load it changes,
  the stretch for timing) at least its kind's ``min_size`` (:data:`SHAPE_KINDS`) — smaller departures are within any model's
  form tolerance and are not called physics — then removed, and the search repeats
  (``MAX_SHAPES``). What significant residual is left above that size is located as in
  :mod:`.locate` and reported as uncharacterised structure.
- **Competing** (:func:`competitors`): a shape that no catalogue mechanism produces can
  replace a mechanism (:mod:`.verdict`): a step, a bump, a timing error, a load-power excess,
  and a change or oscillation carried by one channel only (a mechanism acting on the cutting
  moves both channels). A two-channel oscillation is the feed pulsation's own form and does
  not compete.

The spindle: a spindle that slows under load raises the feed per revolution and the loads,
which a scale or clogging would absorb. Its ripple line tells it (:func:`spindle_line`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import signal

from femstudy.diagnosis.findings import Unexplained
from femstudy.diagnosis.locate import mismatch_intervals
from femstudy.diagnosis.mechanisms.problem import Problem

#: Least BIC gain (Δχ² − k ln n) for a shape to be reported.
MIN_GAIN = 10.0
#: Least residual, as a fraction of the channel's peak modelled load, reported as structure.
MIN_STRUCTURE = 0.03
#: Most shapes reported per diagnosis.
MAX_SHAPES = 3
#: Oscillation frequencies scanned [Hz].
FREQUENCIES_HZ = np.geomspace(0.2, 4.0, 90)
#: Bump widths scanned [s].
BUMP_WIDTHS_S = (0.5, 1.0, 2.0, 3.0)
#: Layer thicknesses scanned for the layer-shaped bump [mm], and lip points in its quadrature.
LAYER_THICKNESS_MM = (0.25, 0.5, 1.0, 2.0)
LIP_POINTS = 24
#: Stretches of the timing shape scanned (fractions, both signs).
STRETCHES = np.geomspace(0.01, 0.2, 20)
#: Delays of the timing shape scanned [s]: the alignment was made without the stretch.
DELAYS_S = np.linspace(-0.3, 0.3, 21)
#: A spindle line this far (fraction) below the stated N/60 is reported.
SPINDLE_DROP = 0.04
#: A spindle line must stand this far (power ratio) above the median of its search band.
SPINDLE_CONTRAST = 30.0

NAME = {"thrust_N": "thrust", "torque_Nmm": "torque"}


@dataclass(frozen=True)
class Shape:
    """A fitted shape: kind, scanned parameters, and per channel its columns, amplitudes
    (zero where the channel does not carry it) and Δχ²."""

    kind: str
    parameters: dict
    used: tuple                # per channel: carries the shape
    columns: tuple             # per channel: smoothed columns (instants × k)
    coefficients: tuple        # per channel: fitted amplitudes
    chi2_gain: tuple           # per channel: Δχ² (0 where not used)
    gain: float                # Σ Δχ² − k ln n
    interval: tuple            # (start_s, end_s)
    n_params: int              # k: amplitudes and scanned parameters
    scanned: int               # scanned parameters (of k)

    @property
    def size(self) -> float:
        """The fraction of the load changed (amplitude for an oscillation, stretch for timing:
        its kind's ``size``)."""
        spec = SHAPE_KINDS[self.kind]
        if spec.size is not None:
            return spec.size(self)
        amounts = [abs(float(b[0])) for b, u in zip(self.coefficients, self.used) if u]
        return max(amounts) if amounts else 0.0

    def contribution(self) -> np.ndarray:
        """The shape's fitted contribution, channels × instants."""
        return np.vstack([A @ b for A, b in zip(self.columns, self.coefficients)])

    def free_columns(self) -> tuple:
        """Per channel, the columns to refit with a model: a fixed first column (timing) enters
        whole as one column with the fitted amplitude's companion; unused channels get none."""
        out = []
        for A, b, u in zip(self.columns, self.coefficients, self.used):
            if not u:
                out.append(())
            elif SHAPE_KINDS[self.kind].fixed_first:
                out.append((A[:, 0], A[:, 1]))
            else:
                out.append(tuple(A.T))
        return tuple(out)

    def one_channel(self) -> bool:
        return len(self.used) == 2 and sum(self.used) == 1


def modelled_loads(problem: Problem, params: dict, t: np.ndarray | None = None) -> tuple[np.ndarray, list[np.ndarray]]:
    """The modelled loads at ``t`` (default the model grid): mechanisms applied, scaled, no
    tare or drift."""
    t = problem.band.t_model if t is None else t
    terms = problem.terms(params, t)
    out = []
    for c in problem.channels:
        load = terms[c] * params.get(f"{c}_scale", 1.0)
        if c == "torque_Nmm" and terms["excess"]:
            load = load + problem.torque_of_excess(params, terms)
        out.append(load)
    return t, out


def cut_span(problem: Problem, params: dict) -> tuple[float, float]:
    """Contact and feed stop on the recording's clock [s] (the window's end if the simulation
    does not stop inside it)."""
    sim = problem.simulation
    shift = params["shift_s"]
    stop = (sim.contact_s + params["stop_depth_mm"] / problem.geometry.feed_mm_s
            if sim.stop_is_parameter else sim.stop_s)
    end = float(problem.band.t_dec[-1])
    return sim.contact_s + shift, min(stop + shift, end) if math.isfinite(stop) else end


@dataclass(frozen=True)
class Span:
    """What the shapes are built on: the modelled ``loads`` at ``t`` (per channel), the cut
    [t0, t1] on the recording's clock (``in_cut`` its instants of ``t``), and the scan's step in
    time [s]."""

    problem: Problem
    t: np.ndarray
    loads: list
    t0: float
    t1: float
    in_cut: np.ndarray
    step: float

    @classmethod
    def of(cls, problem: Problem, params: dict, t: np.ndarray, loads: list) -> "Span":
        t0, t1 = cut_span(problem, params)
        return cls(problem, t, loads, t0, t1, (t >= t0) & (t <= t1), problem.band.sigma_s / 2)

    @property
    def feed_mm_s(self) -> float:
        return self.problem.geometry.feed_mm_s

    @property
    def cone_mm(self) -> float:
        return self.problem.geometry.cone_mm


@dataclass(frozen=True)
class ShapeKind:
    """One generic shape of the residual (a row of the module's table).

    ``candidates(span)`` the scanned parameter sets; ``columns(span, c, L, p)`` the unsmoothed
    columns on channel ``c``'s modelled load ``L`` for candidate ``p`` (``width`` of them);
    ``scanned`` the scanned parameters counted in k; ``interval(span, p)`` where it acts;
    ``refine(span, p)`` candidates around the best one, scanned again; ``size(shape)`` the
    fraction of the load it changes (default: the largest first amplitude of a carrying
    channel), reported when at least ``min_size``; ``fixed_first``: the first column enters
    with coefficient 1 (a re-timing, not an amplitude); ``competes``: it may replace a
    mechanism (:func:`competitors`); ``describe(wording)`` the report's (kind, text) of a
    found shape (:class:`Wording`)."""

    name: str
    candidates: Callable
    columns: Callable
    width: int
    scanned: int
    interval: Callable
    min_size: float
    describe: Callable
    refine: Callable | None = None
    size: Callable | None = None
    fixed_first: bool = False
    competes: bool = True


@dataclass(frozen=True)
class Wording:
    """What a found shape's description reads: the channels it uses (``names``), ``only`` ("thrust
    only" when one channel carries it, else ""), its first amplitudes in % (``pct``) and as a
    phrase (``amounts``), its coefficients by channel and its parameters."""

    names: list
    only: str
    pct: dict
    amounts: str
    coef: dict
    parameters: dict


#: The shapes, by kind, in the order they are scanned.
SHAPE_KINDS: dict[str, ShapeKind] = {}


def _shape_kind(kind: ShapeKind) -> ShapeKind:
    SHAPE_KINDS[kind.name] = kind
    return kind


def _steps(span: Span) -> list[dict]:
    edge = 3 * span.problem.band.sigma_s  # a step at contact or at the stop is the simulation's timing
    return [{"time_s": float(s)} for s in np.arange(span.t0 + edge, span.t1 - edge, span.step)]


def _describe_step(w: Wording) -> tuple[str, str]:
    p = w.parameters
    if w.only:
        one = NAME[w.names[0]]
        return f"{one}_only", (f"{w.only}: from {p['time_s']:.2f} s the {one} changes by {w.pct[w.names[0]]:+.1f} % "
                               f"while the other channel follows the model: friction on the drill's body or in the "
                               f"flutes that loads one channel and not the other, or a change in one sensor channel.")
    return "step", (f"a step at {p['time_s']:.2f} s: {w.amounts} from then on. No catalogue mechanism changes the "
                    f"loads at one instant (a chip plug breaking off, a crack, a slip).")


STEP = _shape_kind(ShapeKind("step", _steps, lambda span, c, L, p: [L * (span.t >= p["time_s"])], 1, 1,
                             lambda span, p: (p["time_s"], span.t1), min_size=0.03, describe=_describe_step))


def _layer_width_and_latest_start(span: Span, d: float) -> tuple[float, float]:
    """A layer of thickness ``d`` [mm] spans the cone and itself; it may start as late as falling
    back at least halfway before the cut ends or the tip leaves the cortex."""
    t_layers = min(span.t1, span.t0 + span.problem.geometry.cortex_mm / span.feed_mm_s)
    w = float((d + span.cone_mm) / span.feed_mm_s)
    return w, t_layers - w + min(d, span.cone_mm) / span.feed_mm_s / 2


def _bumps(span: Span) -> list[dict]:
    """Hann windows that rise and fall back inside the cut (one cut short by contact or the
    stop is not local), and layers."""
    bumps = [{"start_s": float(s), "width_s": w} for w in BUMP_WIDTHS_S
             for s in np.arange(span.t0, span.t1 - w, max(span.step, w / 8))]
    for d in LAYER_THICKNESS_MM:
        w, latest = _layer_width_and_latest_start(span, d)
        bumps += [{"start_s": float(s), "width_s": w, "thickness_mm": d}
                  for s in np.arange(span.t0, latest, max(span.step, w / 8))]
    return bumps


def _layer_neighbours(span: Span, p: dict) -> list[dict]:
    """Layers around a scanned one: thickness ×0.8–1.25, the tip's entry ± half a start step."""
    if "thickness_mm" not in p:
        return []
    out = []
    for d in p["thickness_mm"] * np.geomspace(0.8, 1.25, 7):
        w, latest = _layer_width_and_latest_start(span, d)
        out += [{"start_s": float(s), "width_s": w, "thickness_mm": float(d)}
                for s in p["start_s"] + np.linspace(-0.5, 0.5, 5) * max(span.step, w / 8) if span.t0 <= s < latest]
    return out


#: Along the lip, tip to corner (fraction of R): the layer's quadrature points.
_RADIUS = (np.arange(LIP_POINTS) + 0.5) / LIP_POINTS


def _bump(span: Span, c: int, p: dict) -> np.ndarray:
    """A Hann window, or the share of the lips inside a layer (``thickness_mm``): the lip
    point at radius ρR is ρ·cone behind the tip; thrust weights the lip uniformly, torque by ρ."""
    t = span.t
    if "thickness_mm" not in p:
        u = (t - p["start_s"]) / p["width_s"]
        return np.where((u > 0) & (u < 1), 0.5 * (1 - np.cos(2 * math.pi * u)), 0.0)
    below_top = span.feed_mm_s * (t[:, None] - p["start_s"]) - _RADIUS[None, :] * span.cone_mm
    inside = (below_top >= 0) & (below_top <= p["thickness_mm"])
    weight = _RADIUS if span.problem.channels[c] == "torque_Nmm" else np.ones_like(_RADIUS)
    return inside @ weight / weight.sum()


def _describe_bump(w: Wording) -> tuple[str, str]:
    p = w.parameters
    return (f"{NAME[w.names[0]]}_only" if w.only else "bump",
            f"a local change between {p['start_s']:.2f} and {p['start_s'] + p['width_s']:.2f} s: {w.amounts} "
            f"there{', ' + w.only if w.only else ''}, as from a harder or softer layer of bone.")


BUMP = _shape_kind(ShapeKind("bump", _bumps, lambda span, c, L, p: [L * _bump(span, c, p)], 1, 2,
                             lambda span, p: (p["start_s"], p["start_s"] + p["width_s"]), min_size=0.04,
                             describe=_describe_bump, refine=_layer_neighbours))


def _oscillation_columns(span: Span, c: int, L: np.ndarray, p: dict) -> list[np.ndarray]:
    phase = 2 * math.pi * p["frequency_hz"] * span.t
    return [L * span.in_cut * np.sin(phase), L * span.in_cut * np.cos(phase)]


def _describe_oscillation(w: Wording) -> tuple[str, str]:
    amp = {n: 100 * float(np.hypot(*w.coef[n][:2])) for n in w.names}
    return "oscillation", (f"an oscillation at {w.parameters['frequency_hz']:.2f} Hz in {w.only or 'both channels'}, ±"
                           + " and ±".join(f"{amp[n]:.1f} % of the {NAME[n]}" for n in w.names)
                           + (": a feed pulsation would move thrust and torque together, so this is another "
                              "vibration (fixture, bone support, misalignment)." if w.only else
                              ", not of the feed pulsation's form (its depth lead and coupling do not fit)."))


OSCILLATION = _shape_kind(ShapeKind(
    "oscillation", lambda span: [{"frequency_hz": float(f)} for f in FREQUENCIES_HZ if f * (span.t1 - span.t0) >= 1.5],
    _oscillation_columns, 2, 1, lambda span, p: (span.t0, span.t1), min_size=0.03, describe=_describe_oscillation,
    size=lambda shape: max([float(np.hypot(*b[:2])) for b, u in zip(shape.coefficients, shape.used) if u],
                           default=0.0)))


def _retimed(span: Span, c: int, p: dict) -> np.ndarray:
    return np.interp(span.t0 + (span.t - span.t0 - p["delay_s"]) * (1 + p["stretch"]), span.t, span.loads[c])


def _describe_timing(w: Wording) -> tuple[str, str]:
    stretch = 100 * w.parameters["stretch"]
    scales = " and ".join(f"the {NAME[n]} by {100 * float(w.coef[n][1]):+.1f} %" for n in w.names)
    return "timing", (f"a timing mismatch: after contact the recording runs {abs(stretch):.1f} % "
                      f"{'ahead of' if stretch > 0 else 'behind'} the simulation (its breakthrough and stop come "
                      f"{'earlier' if stretch > 0 else 'later'}), with {scales}: the feed rate or the recording's "
                      f"clock is not the stated one.")


TIMING = _shape_kind(ShapeKind(
    "timing", lambda span: [{"stretch": float(e), "delay_s": float(d)}
                            for e in np.concatenate([-STRETCHES, STRETCHES]) for d in DELAYS_S],
    lambda span, c, L, p: [_retimed(span, c, p) - L, L], 2, 2, lambda span, p: (span.t0, span.t1), min_size=0.02,
    describe=_describe_timing, size=lambda shape: abs(shape.parameters["stretch"]), fixed_first=True))


def _peak(L: np.ndarray) -> float:
    return max(float(np.max(np.abs(L))), 1e-12)


LOAD_POWER = _shape_kind(ShapeKind(
    "load_power", lambda span: [{}], lambda span, c, L, p: [L ** 2 / _peak(L), L], 2, 0,
    lambda span, p: (span.t0, span.t1), min_size=0.04,
    describe=lambda w: ("load_power", f"an excess that grows with the load itself ({w.amounts} at the peak load), as "
                                      f"when the spindle slows under load or the sensor is non-linear.")))


def _gains(problem: Problem, residuals: list[np.ndarray], blocks: list[np.ndarray], width: int, fixed: bool):
    """Per channel and candidate: Δχ² of a GLS fit of the candidate's ``width`` columns, and the
    amplitudes. With ``fixed`` the first column enters with coefficient 1 (not fitted)."""
    gains, coefs = [], []
    for c, (r, X) in enumerate(zip(residuals, blocks)):
        rw = problem.whiten(c, r)
        Xw = problem.whiten(c, X)
        m = X.shape[1] // width
        Xw = Xw.reshape(Xw.shape[0], m, width).transpose(1, 0, 2)   # candidates × instants × width
        if fixed:
            e = rw[None, :] - Xw[:, :, 0]
            free = Xw[:, :, 1:]
        else:
            e = np.broadcast_to(rw, (m, rw.size))
            free = Xw
        G = np.einsum("kiw,kiv->kwv", free, free) + 1e-12 * np.eye(free.shape[2])[None]
        b = np.einsum("kiw,ki->kw", free, e)
        beta = np.linalg.solve(G, b[..., None])[..., 0]
        gain = float(rw @ rw) - (np.einsum("ki,ki->k", e, e) - np.einsum("kw,kw->k", b, beta))
        gains.append(gain)
        coefs.append(np.concatenate([np.ones((m, 1)), beta], axis=1) if fixed else beta)
    return np.array(gains), coefs


def _scan(problem: Problem, residuals: list, span: Span, spec: ShapeKind, candidates: list, one_channel: bool,
          tries: int) -> Shape:
    """The best of ``candidates`` of one kind (and the best channel variant); ``tries`` is the
    number of candidates looked at in all, for the look-elsewhere allowance."""
    n, n_ch = problem.y.size, len(problem.channels)
    variants = [tuple(True for _ in range(n_ch))]
    if n_ch == 2:
        variants += [(True, False), (False, True)]
    width, scanned = spec.width, spec.scanned
    blocks = [problem.band.smooth_model(np.vstack([col for cand in candidates for col in spec.columns(span, c, L, cand)])).T
              for c, L in enumerate(span.loads)]
    fixed = spec.fixed_first
    gains, coefs = _gains(problem, residuals, blocks, width, fixed)
    best = None
    for used in variants:
        if (one_channel and sum(used) != 1) or (fixed and not all(used)):
            continue
        k = (width - fixed) * sum(used) + scanned
        look_elsewhere = 2 * math.log(tries)  # the best of many tries: its expected noise gain
        total = sum(gains[c] for c in range(n_ch) if used[c]) - k * math.log(n) - look_elsewhere
        j = int(np.argmax(total))
        if best is None or total[j] > best[0]:
            best = (float(total[j]), j, used, k)
    gain, j, used, k = best
    return Shape(spec.name, dict(candidates[j]), used,
                 tuple(blk[:, j * width:(j + 1) * width] for blk in blocks),
                 tuple(coefs[c][j] if used[c] else np.zeros(width) for c in range(n_ch)),
                 tuple(float(gains[c][j]) if used[c] else 0.0 for c in range(n_ch)),
                 gain, spec.interval(span, candidates[j]), k, scanned)


def shapes(problem: Problem, params: dict, residuals: list[np.ndarray], kinds=None,
           one_channel_only: tuple = ()) -> list[Shape]:
    """The best candidate of each kind on ``residuals`` (best channel variant), restricted to
    ``kinds`` if given; kinds in ``one_channel_only`` may use one channel only. A kind with a
    local refinement (the layer's thickness and depth) is scanned again around its best."""
    span = Span.of(problem, params, *modelled_loads(problem, params))
    out = []
    for spec in SHAPE_KINDS.values():
        candidates = spec.candidates(span) if kinds is None or spec.name in kinds else []
        if not candidates:
            continue
        scan = lambda cands, tries: _scan(problem, residuals, span, spec, cands, spec.name in one_channel_only, tries)
        best = scan(candidates, len(candidates))
        local = spec.refine(span, best.parameters) if spec.refine else []
        if local:
            finer = scan(local, len(candidates) + len(local))
            best = finer if finer.gain > best.gain else best
        out.append(best)
    return out


def material(shape: Shape) -> bool:
    """Gain and size both large enough to report (``MIN_GAIN``, the kind's ``min_size``)."""
    return shape.gain >= MIN_GAIN and shape.size >= SHAPE_KINDS[shape.kind].min_size


def characterise(problem: Problem, params: dict, residual: np.ndarray) -> list[Shape]:
    """Greedy search of material shapes in ``residual`` (channels × instants), see the module."""
    remaining = [residual[c].copy() for c in range(len(problem.channels))]
    found: list[Shape] = []
    for _ in range(MAX_SHAPES):
        candidates = [s for s in shapes(problem, params, remaining) if material(s)]
        if not candidates:
            break
        best = max(candidates, key=lambda s: s.gain)
        found.append(best)
        remaining = [r - d for r, d in zip(remaining, best.contribution())]
    return found


def competitors(problem: Problem, params: dict, residual: np.ndarray) -> list[Shape]:
    """The material shapes, one per kind, that may explain ``residual`` among those no mechanism
    produces (see the module; an oscillation competes only when one channel carries it),
    largest gain first."""
    one = ("oscillation",) if problem.has_torque else ()
    competing = tuple(k for k, spec in SHAPE_KINDS.items() if spec.competes)
    kinds = competing if problem.has_torque else tuple(k for k in competing if k != "oscillation")
    found = [s for s in shapes(problem, params, [r for r in residual], kinds, one) if material(s)]
    return sorted(found, key=lambda s: -s.gain)


def spindle_line(time_s: np.ndarray, thrust_N: np.ndarray, model_thrust: np.ndarray, spindle_rpm: float,
                 span: tuple[float, float]) -> dict | None:
    """The spindle's ripple line in the loaded cut, when it lies more than ``SPINDLE_DROP``
    below N/60; None otherwise or when no line stands out.

    Parameters
    ----------
    time_s, thrust_N : the raw recording [s], [N].
    model_thrust : the modelled thrust at ``time_s`` [N] (removed before the spectrum).
    spindle_rpm : the stated speed [rpm].
    span : the loaded part of the cut [s].

    Returns
    -------
    dict with the measured and stated line [Hz] and the speed drop (fraction), or None.

    Examples
    --------
    >>> t = np.arange(0, 6, 1e-3)
    >>> F = 20 * (1 + 0.05 * np.sin(2 * np.pi * 15 * t))
    >>> round(spindle_line(t, F, np.full_like(t, 20.0), 1000, (1, 5))["speed_drop"], 2)
    0.1
    """
    inside = (time_s >= span[0]) & (time_s <= span[1])
    if np.count_nonzero(inside) < 256:
        return None
    fs = 1.0 / float(np.median(np.diff(time_s)))
    nominal = spindle_rpm / 60.0
    x = thrust_N[inside] - model_thrust[inside]
    n_fft = 1 << int(math.ceil(math.log2(x.size * 8)))
    f = np.fft.rfftfreq(n_fft, 1.0 / fs)
    power = np.abs(np.fft.rfft(signal.detrend(x) * np.hanning(x.size), n_fft)) ** 2
    best = None
    for harmonic in (1, 2):
        band = (f >= 0.6 * harmonic * nominal) & (f <= 1.1 * harmonic * nominal) & (f < 0.45 * fs)
        if np.count_nonzero(band) < 10:
            continue
        k = int(np.flatnonzero(band)[np.argmax(power[band])])
        contrast = power[k] / float(np.median(power[band]))
        if best is None or contrast > best[1]:
            best = (f[k] / harmonic, contrast)
    if best is None or best[1] < SPINDLE_CONTRAST:
        return None
    resolution = fs / x.size
    drop = 1.0 - best[0] / nominal
    if drop < max(SPINDLE_DROP, 1.5 * resolution / nominal):
        return None
    return {"line_hz": round(float(best[0]), 3), "stated_hz": round(nominal, 3), "speed_drop": round(float(drop), 4)}


def describe(problem: Problem, shape: Shape) -> tuple[str, str, str]:
    """(kind, channel, description) of a shape for the report."""
    names = [c for c, u in zip(problem.channels, shape.used) if u]
    channel = names[0] if len(names) == 1 else "both"
    only = f"{NAME[names[0]]} only" if shape.one_channel() else ""
    coef = dict(zip(problem.channels, shape.coefficients))
    pct = {n: 100 * float(coef[n][0]) for n in names}
    amounts = " and ".join(f"the {NAME[n]} by {pct[n]:+.1f} %" for n in names)
    kind, text = SHAPE_KINDS[shape.kind].describe(Wording(names, only, pct, amounts, coef, shape.parameters))
    return kind, channel, text


def report(problem: Problem, found: list[Shape], leftover: np.ndarray, spindle: dict | None,
           span: tuple[float, float], peak_loads: np.ndarray) -> tuple[Unexplained, ...]:
    """The ``unexplained`` findings: described shapes, the spindle, and located
    residual the shapes leave that is larger than ``MIN_STRUCTURE`` of the peak load."""
    out = []
    if spindle is not None:
        out.append(Unexplained(round(span[0], 3), round(span[1], 3), "both", "spindle",
                               f"the spindle turns slower than stated while cutting: its ripple line is at "
                               f"{spindle['line_hz']:.2f} Hz, {100 * spindle['speed_drop']:.0f} % below "
                               f"N/60 = {spindle['stated_hz']:.2f} Hz, so the feed per revolution and the "
                               f"loads are higher (a spindle slowing under load, or a wrong spindle_rpm).",
                               spindle))
    for s in found:
        kind, channel, text = describe(problem, s)
        out.append(Unexplained(round(float(s.interval[0]), 3), round(float(s.interval[1]), 3), channel, kind, text,
                               {"delta_bic": round(s.gain, 1), "size": round(s.size, 4),
                                **{k: round(v, 4) for k, v in s.parameters.items()}}))
    z = leftover / problem.sigma
    for c, name in enumerate(problem.channels):
        big = np.abs(leftover[c]) >= MIN_STRUCTURE * peak_loads[c]
        for interval in mismatch_intervals(problem.band.t_dec, np.where(big, z[c], 0.0), problem.n_eff_factor, name,
                                           chi2_of=lambda lo, hi, c=c: interval_chi2(problem, c, leftover[c], lo, hi)):
            inside = (problem.band.t_dec >= interval["start_s"]) & (problem.band.t_dec <= interval["end_s"])
            share = 100 * float(np.max(np.abs(leftover[c][inside]))) / peak_loads[c]
            out.append(Unexplained(round(interval["start_s"], 3), round(interval["end_s"], 3), name, "structure",
                                   f"residual structure in the {NAME[name]} that none of the shapes describes "
                                   f"(up to {share:.0f} % of the peak load, max |z| = {interval['max_abs_z']:.1f})",
                                   {"significance": interval["significance"]}))
    return tuple(sorted(out, key=lambda u: (u.start_s, u.channel)))


def interval_chi2(problem: Problem, c: int, r: np.ndarray, lo: int, hi: int) -> float:
    """χ² of channel ``c``'s residual ``r`` over instants lo..hi under the noise model."""
    rows = np.zeros(r.size, dtype=bool)
    rows[lo:hi + 1] = True
    return float(np.sum(problem.whiten(c, r, rows) ** 2))
