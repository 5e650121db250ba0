"""Nonlinear least squares of mechanism subsets, with linear parameters projected out.

For a subset of mechanisms the nonlinear parameters θ (alignment, growth exponent, pulsation,
softening) are fitted with :func:`scipy.optimize.least_squares` (bounded, trust-region
reflective); for each θ the linear ones (tares, drift rates, clogging torque gain, calibration
scales) are the weighted linear least-squares solution (variable projection, :func:`project`).
Residuals are weighted by the noise of each smoothed sample, so the cost is χ²/2.

Starting points (:func:`seeds`, :class:`Linearisation`): a mechanism with a multimodal
parameter scans it (the pulsation's frequency, 0.15–3.5 Hz: the exact linearisation of the
pulsation term in (a, b), load modulation plus depth lead), each candidate fitted together
with the other mechanisms' linear stand-ins, one small linear solve per candidate; its best
local minima of χ² start separate fits. The stand-ins' time constant (softening's) is scanned
the same way, with the best scanned candidate as a shared term. Each mechanism reads its seeds
from these fits. Each subset is also started from the best fit of its subsets with one
mechanism fewer; the best optimum is kept. A mechanism's optional forms (the pulse-shaped and
swept pulsations) are fitted only where the plain one leaves more than noise (:func:`fit_all`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, signal
from scipy.linalg import lapack

from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.mechanisms.registry import catalogue, in_order, nonnegative_linear, owner

#: Time constants of the stand-ins scanned [s], and the one used while another scan runs.
TAU_GRID_S = np.geomspace(0.2, 40.0, 16)
STAND_IN_TAU_S = 2.0
#: Best local minima of a mechanism's scan that start fits.
FREQUENCY_STARTS = 3
#: χ²/dof of the all-mechanism fit above which the pulse-shaped pulsation is tried.
PULSE_GATE = 2.0
#: BIC gain beyond its parameter's cost that the pulse shape must bring.
MIN_PULSE_GAIN = 10.0
#: Multiple of the best subset's gain from a pulsation variant within which the others are refitted.
REACH = 2.0


@dataclass
class Fit:
    """One subset's optimum: parameters, χ² per channel and the smoothed model."""

    subset: frozenset
    params: dict                 # nonlinear and linear parameters by name
    chi2: np.ndarray             # per channel (weighted by the noise of each sample)
    model: np.ndarray            # smoothed model, channels × instants
    n_params: int
    variant: tuple = ()          # optional pulsation parameters fitted (sharpness, sweep)

    @property
    def chi2_total(self) -> float:
        return float(self.chi2.sum())


def _lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least squares for a few columns (tare, drift ramp, torque gain): normal equations, or the
    SVD when a column is (nearly) zero, e.g. the clogging column at p = 0."""
    G = A.T @ A
    d = np.diag(G)
    if d.min() > 1e-10 * d.max():
        _, x, info = lapack.dposv(G, A.T @ b)  # Cholesky: a tenth of np.linalg.solve's overhead
        if info == 0:
            return x
    return np.linalg.lstsq(A, b, rcond=None)[0]


def project(problem: Problem, subset: frozenset, params: dict, rows: np.ndarray | None = None):
    """Whitened residuals on ``rows`` (default all) per channel, the linear parameters fitted
    there, and the smoothed model at all instants, for the nonlinear ``params``. A torque gain
    (k_T = R μ_w l_w / M) is at least 0: fitted negative, it is held at 0."""
    parts = problem.design(subset, params)
    names = problem.linear_names(subset)
    gains = nonnegative_linear()
    residuals, linear, model = [], {}, []
    for c, (base, A) in enumerate(parts):
        target = problem.whiten(c, problem.y[c] - base, rows)
        Aw = problem.whiten(c, A, rows)
        beta = _lstsq(Aw, target)
        negative = [j for j, n in enumerate(names[c]) if n in gains and beta[j] < 0]
        if negative:
            kept = np.delete(np.arange(Aw.shape[1]), negative)
            trailing = kept[-1] == kept.size - 1  # the gains come last: a slice of the columns
            beta = np.insert(_lstsq(Aw[:, :kept.size] if trailing else Aw[:, kept], target),
                             np.array(negative) - np.arange(len(negative)), 0.0)
        linear.update(zip(names[c], beta))
        residuals.append(target - Aw @ beta)
        model.append(base + A @ beta)
    for name in gains & linear.keys():  # per newton of recorded extra thrust, g_F·C
        linear[name] /= linear.get("thrust_N_scale", 1.0) or 1.0
    return residuals, linear, np.vstack(model)


def fit_subset(problem: Problem, subset: frozenset, starts: list[dict], rows: np.ndarray | None = None,
               variant: tuple = (), fixed: dict | None = None) -> Fit:
    """The best of several bounded least-squares fits of one subset, on ``rows`` (default all),
    with the nonlinear parameters in ``fixed`` held at their values."""
    fixed = fixed or {}
    names = [n for n in problem.nonlinear_names(subset, variant) if n not in fixed]
    lo, hi = problem.bounds(names)
    best = None
    if not names:
        starts = []
    for start in starts:
        x0 = np.clip([start[n] for n in names], lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))

        def fun(x):
            res, _, _ = project(problem, subset, {**fixed, **dict(zip(names, x))}, rows)
            return np.concatenate(res)

        sol = optimize.least_squares(fun, x0, bounds=(lo, hi), method="trf", x_scale="jac",
                                     ftol=1e-5, xtol=1e-5, max_nfev=20 * (len(names) + 1))
        if best is None or sol.cost < best.cost:
            best = sol
    params = {**fixed, **dict(zip(names, best.x if best is not None else []))}
    res, linear, model = project(problem, subset, params, rows)
    chi2 = np.array([float(np.sum(r ** 2)) for r in res])
    n_linear = sum(len(n) for n in problem.linear_names(subset))
    return Fit(subset, {**params, **linear}, chi2, model, len(names) + len(fixed) + n_linear, tuple(variant))


def fit_each(requests: list) -> list[Fit]:
    """``fit_subset(problem, subset, starts, **options)`` for each request ``(problem, subset,
    starts, options)``, one after the other: the serial fitter (:mod:`.workers` has the
    parallel one)."""
    return [fit_subset(problem, subset, starts, **options) for problem, subset, starts, options in requests]


def _stand_in_columns(problem: Problem, base_params: dict, tau_s: float) -> list[np.ndarray]:
    """Linear stand-ins per channel: the alignment's columns (scale, tare), the mechanisms'
    sensor columns (a drift ramp), then their stand-ins (clogging at its nominal growth,
    softening at ``tau_s``), smoothed."""
    plain = problem.terms(base_params)
    stand_ins = [m.stand_in(problem, base_params, plain, tau_s) for m in catalogue() if m.stand_in is not None]
    sensor = [term.column(problem) for m in catalogue() for term in m.linear]
    aligned = problem.design(frozenset(), base_params)
    cols = []
    for c, (_, A) in zip(problem.channels, aligned):
        smooth = problem.band.smooth_model(np.vstack([s[c] for s in stand_ins]))
        cols.append(np.column_stack([A, *sensor, *smooth]))
    return cols


def _scan(problem: Problem, base_params: dict, shared_of, tau_s: float):
    """For each (key, shared columns) of ``shared_of()``: the χ² and coefficients of a joint
    linear fit of both channels on the shared columns plus each channel's stand-ins."""
    stand_in = _stand_in_columns(problem, base_params, tau_s)
    base = problem.design(frozenset(), base_params)
    n_channels = len(problem.channels)
    targets = [problem.whiten(c, problem.y[c] - base[c][0]) for c in range(n_channels)]
    own_w = [problem.whiten(c, stand_in[c]) for c in range(n_channels)]
    results = []
    for key, shared in shared_of():
        blocks = []
        for c in range(n_channels):
            own = [np.zeros_like(stand_in[k]) for k in range(n_channels)]
            own[c] = own_w[c]
            blocks.append(np.column_stack([problem.whiten(c, shared[c])] + own))
        A, b = np.vstack(blocks), np.concatenate(targets)
        coef, *_ = np.linalg.lstsq(A, b, rcond=None)
        results.append((key, float(np.sum((b - A @ coef) ** 2)), coef))
    return results


@dataclass(frozen=True)
class Linearisation:
    """The linearised fits the seeds are read from: per scanning mechanism its best candidates
    (key, χ², coefficients with its own columns first), the stand-ins' best time constant, and
    each stand-in's thrust coefficient there (per unit of the calibration scale)."""

    scans: dict
    tau_s: float
    stand_ins: dict


def linearise(problem: Problem, base_params: dict) -> Linearisation:
    """Each scanning mechanism's scan (best few local minima of χ²), then the stand-ins' time
    constant with the best candidates as a shared term (see the module docstring)."""
    scans, best = {}, []
    for m in catalogue():
        if m.scan is None:
            continue

        def candidates(m=m):
            for key in m.scan.grid(problem):
                yield key, [c.T for c in m.scan.columns(problem, base_params, key)]

        scan = _scan(problem, base_params, candidates, tau_s=STAND_IN_TAU_S)
        chi2 = np.array([r[1] for r in scan])
        peaks = signal.argrelmin(np.concatenate([[np.inf], chi2, [np.inf]]))[0] - 1
        scans[m.name] = [scan[k] for k in peaks[np.argsort(chi2[peaks])][:FREQUENCY_STARTS]]
        key = scans[m.name][0][0] if scans[m.name] else m.scan.default
        best.append([c.T for c in m.scan.columns(problem, base_params, key)])
    if len(best) == 1:
        shared = best[0]
    else:  # several scanning mechanisms side by side, or none
        shared = [np.hstack(cols) if cols else np.zeros((problem.band.t_dec.size, 0))
                  for cols in (zip(*best) if best else [()] * len(problem.channels))]
    by_tau = []
    for tau_s in TAU_GRID_S:
        (_, value, coef), = _scan(problem, base_params, lambda: [(tau_s, shared)], tau_s=tau_s)
        by_tau.append((value, tau_s, coef))
    _, tau_s, coef = min(by_tau, key=lambda r: r[0])
    width = shared[0].shape[1]
    n_aligned = len(problem.linear_names(frozenset())[0])
    n_sensor = sum(len(m.linear) for m in catalogue())
    with_stand_in = [m.name for m in catalogue() if m.stand_in is not None]
    thrust_coef = coef[width:width + n_aligned + n_sensor + len(with_stand_in)]  # after the shared columns
    scale = thrust_coef[0] if problem.calibrate else 1.0
    own = thrust_coef[len(thrust_coef) - len(with_stand_in):]
    return Linearisation(scans, float(tau_s), {name: k / scale for name, k in zip(with_stand_in, own)})


def seeds(problem: Problem, base_params: dict) -> dict:
    """Starting values of each mechanism (name -> list of dicts, the first the default), read
    from the linearised scans."""
    linearisation = linearise(problem, base_params)
    return {m.name: m.seeds(problem, linearisation) for m in catalogue()}


def starting_points(subset: frozenset, base_params: dict, seed: dict, smaller: dict) -> list[dict]:
    """Starts for one subset: the seeds, and the best fit of a subset with one mechanism fewer
    completed by the seeds. A mechanism alone is started from each of its seeds (the
    pulsation at every candidate frequency); larger subsets inherit them through the smaller
    fits."""
    fixed = dict(base_params)
    for m in catalogue():
        if m.name in subset:
            fixed.update(seed[m.name][0])
    starts = [fixed]
    if len(subset) == 1:
        starts += [{**fixed, **s} for s in seed[next(iter(subset))][1:]]
    previous = [smaller[subset - {m}] for m in in_order(subset) if subset - {m} in smaller]
    if previous:
        best = min(previous, key=lambda f: f.chi2_total)
        starts.append({**fixed, **best.params})
    return starts


def _variant_stage(problem: Problem, fits: dict, name: str, starts: tuple, fits_of=fit_each) -> None:
    """Refit the subsets with the mechanism of the optional parameter ``name`` (the pulsation's
    sharpness or sweep) adding it: first the best
    one, from each value in ``starts``; if it gains more than the parameter's BIC cost plus
    ``MIN_PULSE_GAIN`` there, every other one from the value found, kept where it gains as much.
    A subset that would stay behind the best one's refit even gaining twice as much
    (``REACH``) is left as it is: no selection can pick it (the all-mechanism subset, whose
    misfit scales the BIC, is always refitted)."""
    factor = problem.n_eff_factor
    cost = math.log(problem.y.size * factor) + MIN_PULSE_GAIN
    pulsed = sorted((s for s in fits if owner(name).name in s), key=lambda s: fits[s].chi2_total)
    full = max(fits, key=len)
    best = None
    for subset in pulsed:
        plain = fits[subset]
        if best is not None and subset != full and (
                (plain.chi2_total - best[0]) * factor > REACH * best[1] + cost):
            continue
        variant = plain.variant + (name,)
        refit, = fits_of([(problem, subset, [{**plain.params, name: v} for v in starts], {"variant": variant})])
        if (plain.chi2_total - refit.chi2_total) * factor <= cost:
            if subset == pulsed[0]:
                return  # no gain where pulsation fits best: the plain form stays everywhere
            continue
        fits[subset] = refit
        starts = (refit.params[name],)
        if best is None:
            best = (refit.chi2_total, (plain.chi2_total - refit.chi2_total) * factor)


def fit_all(problem: Problem, base_params: dict, seed: dict, fits_of=fit_each) -> dict:
    """Fits of every subset of mechanisms (in order of size, each seeding the larger ones; the
    subsets of one size by ``fits_of``, :mod:`.workers`).

    When even the fit with all mechanisms leaves clearly more than noise (χ²/dof above
    ``PULSE_GATE``), the mechanisms' optional forms are tried (:func:`_variant_stage`): the
    pulsation's pulse shape (sharpness κ, from 1.5 and 4), then a sweep of its frequency (r,
    from ±0.2), each on top of the subsets' forms so far. A mechanism the recording cannot show
    (clogging without a chip column) is left out."""
    allowed = [m.name for m in catalogue() if m.can_show(problem)]
    subsets = [frozenset(m for k, m in enumerate(allowed) if mask >> k & 1) for mask in range(1 << len(allowed))]
    fits: dict = {}
    for size in range(len(allowed) + 1):
        level = [s for s in subsets if len(s) == size]
        requests = [(problem, s, starting_points(s, base_params, seed, fits), {}) for s in level]
        fits.update(zip(level, fits_of(requests)))
    full = fits[max(fits, key=len)]
    factor = problem.n_eff_factor
    if full.chi2_total * factor / max(problem.y.size * factor - full.n_params, 1.0) > PULSE_GATE:
        for m in catalogue():
            for variant in m.variants:
                _variant_stage(problem, fits, variant.parameter, variant.starts, fits_of)
    return fits
