"""What the best catalogue model leaves: searched with the registered shapes, reported as "unexplained".

The residual of each channel is searched for structure of the shapes of :mod:`.shapes`, each a
few columns on the modelled load L_c (the fitted simulation with its mechanisms), fitted by GLS
under the recording's noise model. Each shape is fitted to both channels (own amplitudes) or to
one alone; the variant with the larger gain Δχ² − k ln n − 2 ln m wins (k its columns and scanned
parameters, m the candidates scanned: the best of m tries on pure noise gains about 2 ln m).

Two uses:

- **Characterising** (:func:`characterise`): on the final residual, the best shape is kept when
  its gain is at least ``MIN_GAIN`` and its size at least the shape's ``min_size`` — smaller
  departures are within any model's form tolerance — then removed, and the search repeats
  (``MAX_SHAPES``). Significant residual above ``MIN_STRUCTURE`` of the peak load that remains
  is located (:mod:`.locate`) and reported as ``structure``.
- **Competing** (:func:`competitors`): a shape that no catalogue mechanism produces may replace
  mechanisms (:mod:`.verdict`); those that could be a mechanism's own form on both channels (an
  oscillation) compete only on one channel.

The spindle: a spindle that slows under load raises the feed per revolution and the loads, which
a scale or clogging would absorb; its ripple line tells it (:func:`spindle_line`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from femstudy.diagnosis.fit import Fit
from femstudy.diagnosis.fitpool import FitPool
from femstudy.diagnosis.locate import mismatch_intervals
from femstudy.diagnosis.problem import Problem
from femstudy.diagnosis.shapes import SHAPES, WORD, Context

MIN_GAIN = 10.0
MIN_STRUCTURE = 0.03
MAX_SHAPES = 3
#: Rounds of a shape's local refinement around its best candidate, while the gain grows.
REFINEMENTS = 3
SPINDLE_DROP = 0.04
SPINDLE_CONTRAST = 30.0


@dataclass(frozen=True)
class Shape:
    """A fitted shape: kind, scanned parameters, and per channel whether it is used, its smoothed
    columns (instants × k), amplitudes and Δχ²; the gain and the interval it covers."""

    kind: str
    parameters: dict[str, float]
    used: tuple
    columns: tuple
    coefficients: tuple
    chi2_gain: tuple
    gain: float
    interval: tuple
    n_params: int
    scanned: int

    @property
    def size(self) -> float:
        return SHAPES[self.kind].size(self.parameters, self.coefficients, self.used)

    def contribution(self) -> np.ndarray:
        return np.vstack([A @ b for A, b in zip(self.columns, self.coefficients)])

    def free_columns(self) -> tuple:
        """Per channel, the columns to refit with a model: a fixed first column (a re-timing) enters
        whole beside its companion; unused channels get none."""
        out = []
        for A, b, u in zip(self.columns, self.coefficients, self.used):
            if not u:
                out.append(())
            elif SHAPES[self.kind].fixed_first:
                out.append((A[:, 0], A[:, 1]))
            else:
                out.append(tuple(A.T))
        return tuple(out)

    def one_channel(self) -> bool:
        return len(self.used) == 2 and sum(self.used) == 1


@dataclass(frozen=True)
class Unexplained:
    """An ``unexplained`` entry of the contract."""

    start_s: float
    end_s: float
    channel: str
    kind: str
    description: str
    evidence: tuple[tuple[str, float], ...] = ()

    def to_json(self) -> dict:
        return {"start_s": round(self.start_s, 3), "end_s": round(self.end_s, 3), "channel": self.channel,
                "kind": self.kind, "description": self.description, "evidence": dict(self.evidence)}


def context(problem: Problem, f: Fit) -> Context:
    frame = f.evaluation.frame
    end = float(problem.band.t_dec[-1])
    g = problem.geometry
    return Context(problem.band.t_model, (frame.contact_t_s, min(frame.stop_t_s, end)), problem.band.sigma_s / 2,
                   problem.band.sigma_s, g.feed_mm_s, g.cone_mm, g.cortex_mm, problem.channels,
                   float(np.median(np.diff(problem.band.t_dec))))


def _distinct_smoothed(problem: Problem, columns: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Columns on the model grid at the band's instants (instants × distinct columns), each array
    smoothed once however many candidates return it (the timing shape's every candidate returns
    the load itself), and which of them each column is."""
    first: dict[int, int] = {}
    distinct, positions = [], []
    for column in columns:   # all alive in ``columns``, so no two share an id
        k = first.get(id(column))
        if k is None:
            k = first[id(column)] = len(distinct)
            distinct.append(column)
        positions.append(k)
    return problem.band.smooth_columns(np.column_stack(distinct)), np.array(positions)


def _gains(problem: Problem, residuals: list[np.ndarray], blocks: list[tuple[np.ndarray, np.ndarray]], width: int,
           fixed: bool):
    """Per channel and candidate: Δχ² of a GLS fit of the candidate's ``width`` columns, and the
    amplitudes; with ``fixed`` the first column enters with coefficient 1. ``blocks``: per channel
    the distinct smoothed columns and which each candidate's column is (:func:`_distinct_smoothed`),
    whitened once each."""
    rows = problem.usable
    gains, coefs = [], []
    for c, (r, (X, positions)) in enumerate(zip(residuals, blocks)):
        rw = problem.whiten(c, r, rows)
        Xw = problem.whiten(c, X, rows)[:, positions]
        m = positions.size // width
        Xw = Xw.reshape(Xw.shape[0], m, width).transpose(1, 0, 2)
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


def _scan(problem: Problem, ctx: Context, residuals: list, loads: np.ndarray, kind: str, candidates: list,
          one_channel: bool, tries: int) -> Shape:
    shape = SHAPES[kind]
    n, n_ch = problem.n, len(problem.channels)
    variants = [tuple(True for _ in range(n_ch))]
    if n_ch == 2:
        variants += [(True, False), (False, True)]
    blocks = [_distinct_smoothed(problem, [col for cand in candidates for col in shape.columns(ctx, c, load, cand)])
              for c, load in enumerate(loads)]   # one array per channel, so that a column returning it is one column
    width, fixed = shape.width, shape.fixed_first
    gains, coefs = _gains(problem, residuals, blocks, width, fixed)
    best = None
    for used in variants:
        if (one_channel and sum(used) != 1) or (fixed and not all(used)):
            continue
        k = (width - fixed) * sum(used) + shape.scanned
        total = sum(gains[c] for c in range(n_ch) if used[c]) - k * math.log(n) - 2 * math.log(max(tries, 1))
        j = int(np.argmax(total))
        if best is None or total[j] > best[0]:
            best = (float(total[j]), j, used, k)
    gain, j, used, k = best
    return Shape(kind, dict(candidates[j]), used, tuple(X[:, positions[j * width:(j + 1) * width]] for X, positions in blocks),
                 tuple(coefs[c][j] if used[c] else np.zeros(width) for c in range(n_ch)),
                 tuple(float(gains[c][j]) if used[c] else 0.0 for c in range(n_ch)),
                 gain, shape.interval(ctx, candidates[j]), k, shape.scanned)


def _best_of_kind(problem: Problem, item: tuple) -> Shape | None:
    """The best candidate of one kind (:func:`shapes`); ``item`` = (context, residuals, loads,
    kind, one channel only)."""
    ctx, residuals, loads, kind, one_channel = item
    shape = SHAPES[kind]
    candidates = shape.candidates(ctx)
    if not candidates:
        return None
    best = _scan(problem, ctx, residuals, loads, kind, candidates, one_channel, len(candidates))
    tries = len(candidates)
    for _ in range(REFINEMENTS):
        local = shape.refine(ctx, best.parameters)
        if not local:
            break
        tries += len(local)
        finer = _scan(problem, ctx, residuals, loads, kind, local, one_channel, tries)
        if finer.gain <= best.gain:
            break
        best = finer
    return best


def shapes(problem: Problem, f: Fit, residuals: list[np.ndarray], kinds=None, one_channel_only: tuple = (),
           pool: FitPool | None = None) -> list[Shape]:
    """The best candidate of each kind on ``residuals`` (best channel variant), for ``kinds`` (default
    all); kinds in ``one_channel_only`` may use one channel only. With a :class:`.fitpool.FitPool`
    the kinds are scanned side by side."""
    ctx = context(problem, f)
    loads = f.evaluation.loads
    items = [(ctx, residuals, loads, kind, kind in one_channel_only) for kind in SHAPES
             if kinds is None or kind in kinds]
    pool = FitPool(problem, workers=1) if pool is None else pool
    return [s for s in pool.run(_best_of_kind, items) if s is not None]


def material(shape: Shape) -> bool:
    return shape.gain >= MIN_GAIN and shape.size >= SHAPES[shape.kind].min_size


def characterise(problem: Problem, f: Fit, residual: np.ndarray, pool: FitPool | None = None) -> list[Shape]:
    """Greedy search of material shapes in ``residual`` (channels × instants); ``pool``: see
    :func:`shapes`."""
    remaining = [residual[c].copy() for c in range(len(problem.channels))]
    found: list[Shape] = []
    for _ in range(MAX_SHAPES):
        candidates = [s for s in shapes(problem, f, remaining, pool=pool) if material(s)]
        if not candidates:
            break
        best = max(candidates, key=lambda s: s.gain)
        found.append(best)
        remaining = [r - d for r, d in zip(remaining, best.contribution())]
    return found


def competitors(problem: Problem, f: Fit, residual: np.ndarray) -> list[Shape]:
    """The material competing shapes on ``residual``, one per kind, largest gain first."""
    kinds = [k for k, s in SHAPES.items() if s.competes and (problem.has_torque or not s.one_channel_competes)]
    one = tuple(k for k in kinds if SHAPES[k].one_channel_competes)
    found = [s for s in shapes(problem, f, [r for r in residual], kinds, one) if material(s)]
    return sorted(found, key=lambda s: -s.gain)


def describe(problem: Problem, shape: Shape) -> tuple[str, str, str]:
    """(kind, channel, description) of a shape for the report."""
    names = [c for c, u in zip(problem.channels, shape.used) if u]
    channel = names[0] if len(names) == 1 else "both"
    coefficients = dict(zip(problem.channels, shape.coefficients))
    kind, text = SHAPES[shape.kind].describe(names, coefficients, shape.parameters, shape.one_channel())
    return kind, channel, text


def _line(time_s: np.ndarray, x: np.ndarray, bands: list[tuple[float, float, int]]) -> tuple[float, float] | None:
    """The strongest line (frequency / harmonic, contrast over the band's median) in ``bands``
    (lo, hi, harmonic) of the Hann-windowed, detrended ``x``."""
    fs = 1.0 / float(np.median(np.diff(time_s)))
    n_fft = 1 << int(math.ceil(math.log2(x.size * 8)))
    f = np.fft.rfftfreq(n_fft, 1.0 / fs)
    power = np.abs(np.fft.rfft(signal.detrend(x) * np.hanning(x.size), n_fft)) ** 2
    best = None
    for lo, hi, harmonic in bands:
        band = (f >= lo) & (f <= hi) & (f < 0.45 * fs)
        if np.count_nonzero(band) < 10:
            continue
        k = int(np.flatnonzero(band)[np.argmax(power[band])])
        contrast = power[k] / float(np.median(power[band]))
        if best is None or contrast > best[1]:
            best = (f[k] / harmonic, contrast)
    return best


def spindle_line(time_s: np.ndarray, thrust_N: np.ndarray, model_thrust: np.ndarray, spindle_rpm: float,
                 span: tuple[float, float], air: np.ndarray | None = None) -> dict | None:
    """The spindle's ripple line in the loaded cut, when it lies more than ``SPINDLE_DROP`` below
    N/60; None otherwise, when no line stands out, or when the same line stands out in air
    (samples ``air``; mains interference is there too, a load's ripple is not).

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
    best = _line(time_s[inside], x, [(0.6 * h * nominal, 1.1 * h * nominal, h) for h in (1, 2)])
    if best is None or best[1] < SPINDLE_CONTRAST:
        return None
    if air is not None and np.count_nonzero(air) >= 256:
        runs = np.flatnonzero(np.diff(np.concatenate([[0], air.astype(int), [0]])))
        i, j = max(zip(runs[::2], runs[1::2]), key=lambda r: r[1] - r[0])
        if j - i >= 256:
            for h in (1, 2):
                width = 0.02 * h * best[0]
                there = _line(time_s[i:j], thrust_N[i:j], [(h * best[0] - width, h * best[0] + width, h),
                                                           (0.6 * h * nominal, 1.1 * h * nominal, h)])
                if there is not None and abs(there[0] - best[0]) < 0.02 * best[0] and there[1] >= SPINDLE_CONTRAST / 3:
                    return None
    resolution = fs / x.size
    drop = 1.0 - best[0] / nominal
    if drop < max(SPINDLE_DROP, 1.5 * resolution / nominal):
        return None
    return {"line_hz": round(float(best[0]), 3), "stated_hz": round(nominal, 3), "speed_drop": round(float(drop), 4)}


def interval_chi2(problem: Problem, c: int, r: np.ndarray, lo: int, hi: int) -> float:
    """χ² of channel ``c``'s residual ``r`` over instants lo..hi under the noise model."""
    rows = np.zeros(r.size, dtype=bool)
    rows[lo:hi + 1] = True
    return float(np.sum(problem.whiten(c, r, rows & problem.usable) ** 2))


def report(problem: Problem, found: list[Shape], leftover: np.ndarray, spindle: dict | None,
           span: tuple[float, float], peak_loads: np.ndarray) -> list[Unexplained]:
    """The shapes, the spindle, and located residual above ``MIN_STRUCTURE`` of the peak load."""
    out = []
    if spindle is not None:
        out.append(Unexplained(span[0], span[1], "both", "spindle",
                               f"the spindle turns slower than stated while cutting: its ripple line is at "
                               f"{spindle['line_hz']:.2f} Hz, {100 * spindle['speed_drop']:.0f} % below N/60 = "
                               f"{spindle['stated_hz']:.2f} Hz, so the feed per revolution and the loads are higher "
                               f"(a spindle slowing under load, or a wrong spindle_rpm).",
                               tuple((k, float(v)) for k, v in spindle.items())))
    for s in found:
        kind, channel, text = describe(problem, s)
        out.append(Unexplained(float(s.interval[0]), float(s.interval[1]), channel, kind, text,
                               (("delta_bic", round(s.gain, 1)), ("size", round(s.size, 4)))
                               + tuple((k, round(float(v), 4)) for k, v in s.parameters.items())))
    z = leftover / problem.sigma
    t = problem.band.t_dec
    for c, name in enumerate(problem.channels):
        big = (np.abs(leftover[c]) >= MIN_STRUCTURE * peak_loads[c]) & problem.usable
        for interval in mismatch_intervals(t, np.where(big, z[c], 0.0), problem.n_eff_factor, name,
                                           chi2_of=lambda lo, hi, c=c: interval_chi2(problem, c, leftover[c], lo, hi)):
            inside = (t >= interval["start_s"]) & (t <= interval["end_s"])
            share = 100 * float(np.max(np.abs(leftover[c][inside]))) / peak_loads[c]
            out.append(Unexplained(interval["start_s"], interval["end_s"], name, "structure",
                                   f"residual structure in the {WORD[name]} that none of the shapes describes (up to "
                                   f"{share:.0f} % of the peak load, max |z| = {interval['max_abs_z']:.1f})",
                                   (("significance", interval["significance"]),)))
    return sorted(out, key=lambda u: (u.start_s, u.channel))
