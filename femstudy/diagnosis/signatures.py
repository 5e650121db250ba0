"""The figures the mechanisms' signature tests rest on (:meth:`~.catalogue.Mechanism.checks`).

Each is a refit or a restricted fit, asked for by name through :func:`refitter`:

- ``gain``: χ² of the fit without the mechanism less the fit's.
- ``lead``: χ² of the fit with the pulsation's depth lead switched off (the loads modulated, the
  depth at the nominal feed) less the fit's.
- ``separate_channels``: the fit with the mechanism's own columns (its derivatives at the fitted
  point) added once more on the torque alone with free amplitudes — the torque allowed its own
  modulation or loss. Returns the BIC gain Δχ² − k ln n over the shared form.
- ``in_air``: on the instants surely in air, the final residual fitted with sines and cosines at
  the pulsation's frequencies (each channel on its own). Returns the BIC gain.
- ``halves``: the pulsation's waveform (its harmonics' sines and cosines) fitted separately in the
  first and second half of the cut. Returns the larger swing over the smaller, and the waveforms'
  similarity 1 − |a₁ − a₂|²/(|a₁|² + |a₂|²) (1: the same wave, 0: unrelated); None if a half holds
  less than a period.
- ``without_in_air``: the fit refitted without the mechanism; returns how much worse it is on the
  instants surely in air, χ² beyond the mechanism's parameters counted at ln n_air each.
- ``signed``: χ² the fit gains when the mechanism's monotone spline may also fall (its coefficients
  of either sign: the ``signed`` variant).
- ``air_explained``: the share of what the load-free instants show beyond the noise model (their
  χ² without the mechanism less their count) that the mechanism removes.
- ``periodic``: what the pulsation gains over the fit without it, less what a smooth, non-periodic
  modulation of both loads gains there with as many coefficients (cubic B-splines over the cut):
  a slow misfit of another mechanism's form is as well fitted by a smooth modulation, a feed
  pulsation of two periods or more is not.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import BSpline

from femstudy.diagnosis.catalogue.feed_pulsation import NAME as PULSATION, waveforms
from femstudy.diagnosis.catalogue import MECHANISMS, Variant
from femstudy.diagnosis.fit import Fit, fit
from femstudy.diagnosis.model import Spec


def smooth_basis(t: np.ndarray, start: float, end: float, count: int) -> np.ndarray:
    """``count`` cubic B-splines with uniform knots over [start, end] (zero outside), at ``t``."""
    degree = min(3, count - 1)
    inner = np.linspace(start, end, count - degree + 1)
    knots = np.concatenate([[start] * degree, inner, [end] * degree])
    inside = (t >= start) & (t <= end)
    out = np.zeros((t.size, count))
    out[inside] = BSpline.design_matrix(t[inside], knots, degree).toarray()
    return out


def _chi2(problem, f_model: np.ndarray, rows: np.ndarray) -> float:
    return float(sum(np.sum(problem.whiten(c, problem.y[c] - f_model[c], rows) ** 2)
                     for c in range(len(problem.channels))))


def refitter(problem, mechanism: str, without_fits: dict | None = None):
    """``refit(kind, fit)`` for ``mechanism``'s checks (see the module docstring).
    ``without_fits``: fits of ``f.spec.without(mechanism)`` from ``f.params()`` already made, by
    ``id(f)`` (the selection's drop-one refits are those)."""
    n = math.log(max(problem.n, 3))
    cache: dict = dict(without_fits or {})

    def without(f: Fit) -> Fit:
        if id(f) not in cache:
            cache[id(f)] = fit(problem, f.spec.without(mechanism), f.params())
        return cache[id(f)]

    def gain(f: Fit) -> float:
        return without(f).chi2_total - f.chi2_total

    def separate(f: Fit) -> float:
        block = f.layout.blocks[mechanism]
        columns = f.evaluation.jacobian[1][:, block]
        keep = np.flatnonzero(np.linalg.norm(columns, axis=0) > 0)
        extra = (tuple(), tuple(columns[:, k] for k in keep))
        wider = fit(problem, f.spec.with_extra(extra), f.params())
        return f.chi2_total - wider.chi2_total - keep.size * n

    def in_air(f: Fit) -> float | None:
        rows = problem.air & problem.usable
        if np.count_nonzero(rows) < 8:
            return None
        frequency, sweep, harmonics = MECHANISMS[PULSATION].frequency(problem, f)
        w = waveforms(problem, problem.band.t_model, frequency, sweep, harmonics)
        smooth = problem.band.smooth_model(w.T).T
        gain = 0.0
        for c in range(len(problem.channels)):
            r = problem.whiten(c, problem.y[c] - f.model[c], rows)
            A = problem.whiten(c, smooth, rows)
            coef, *_ = np.linalg.lstsq(A, r, rcond=None)
            gain += float(r @ (A @ coef)) - A.shape[1] * math.log(max(np.count_nonzero(rows), 3))
        return gain

    def halves(f: Fit) -> tuple[float, float] | None:
        frequency, _, harmonics = MECHANISMS[PULSATION].frequency(problem, f)
        t = problem.band.t_dec
        start, length = problem.contact_t, problem.cut_s
        if length * frequency < 2.0:
            return None
        h = 2 * harmonics
        block = f.layout.blocks[mechanism]
        J = f.evaluation.jacobian[:, :, block][:, :, :h]
        own = np.einsum("cik,k->ci", J, f.block(mechanism)[:h])
        waves = []
        for lo, hi in ((start, start + length / 2), (start + length / 2, start + length)):
            rows = problem.usable & (t >= lo) & (t < hi)
            if np.count_nonzero(rows) < h + 2:
                return None
            A = np.vstack([problem.whiten(c, J[c], rows) for c in range(len(problem.channels))])
            b = np.concatenate([problem.whiten(c, problem.y[c] - f.model[c] + own[c], rows)
                                for c in range(len(problem.channels))])
            coef, *_ = np.linalg.lstsq(A, b, rcond=None)
            waves.append(coef)
        a1, a2 = waves
        norms = sorted([float(np.linalg.norm(a1)), float(np.linalg.norm(a2))])
        similarity = 1 - float(np.sum((a1 - a2) ** 2)) / max(float(np.sum(a1 ** 2) + np.sum(a2 ** 2)), 1e-300)
        return norms[1] / max(norms[0], 1e-12), similarity

    def without_in_air(f: Fit) -> float:
        rows = problem.air & problem.usable
        less = without(f)
        k = f.layout.blocks[mechanism].stop - f.layout.blocks[mechanism].start
        return _chi2(problem, less.model, rows) - _chi2(problem, f.model, rows) - k * math.log(max(np.count_nonzero(rows), 3))

    def air_explained(f: Fit) -> float:
        rows = problem.air & problem.usable
        count = np.count_nonzero(rows) * len(problem.channels)
        before, after = _chi2(problem, without(f).model, rows), _chi2(problem, f.model, rows)
        return (before - after) / max(before - count, 1e-12)

    def periodic(f: Fit) -> float:
        less = without(f)
        count = 2 * MECHANISMS[PULSATION].frequency(problem, f)[2]
        t = problem.band.t_model
        frame = less.evaluation.frame
        B = smooth_basis(t, frame.contact_t_s, frame.stop_t_s, count)
        rows = problem.usable
        A = np.vstack([problem.whiten(c, problem.band.smooth_model((less.evaluation.loads[c][:, None] * B).T).T, rows)
                       for c in range(len(problem.channels))])
        r = np.concatenate([problem.whiten(c, problem.y[c] - less.model[c], rows) for c in range(len(problem.channels))])
        coef, *_ = np.linalg.lstsq(A, r, rcond=None)
        return (less.chi2_total - f.chi2_total) - float(r @ (A @ coef))

    def with_setting(f: Fit, key: str) -> Spec:
        return Spec(tuple((n, Variant(tuple(x.settings) + ((key, True),), x.label) if n == mechanism else x)
                          for n, x in f.spec.variants), f.spec.extra)

    def lead(f: Fit) -> float:
        return fit(problem, with_setting(f, "without_lead"), f.params()).chi2_total - f.chi2_total

    def signed(f: Fit) -> float:
        return f.chi2_total - fit(problem, with_setting(f, "signed"), f.params()).chi2_total

    kinds = {"air_explained": air_explained, "lead": lead, "signed": signed, "separate_channels": separate, "in_air": in_air, "halves": halves, "without_in_air": without_in_air,
             "periodic": periodic, "gain": gain}
    return lambda kind, f: kinds[kind](f)
