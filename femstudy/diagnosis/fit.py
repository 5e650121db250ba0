"""Nonlinear least squares of mechanism subsets, with linear parameters projected out.

For a subset of mechanisms the nonlinear parameters θ (alignment, growth exponent, pulsation,
softening) are fitted with :func:`scipy.optimize.least_squares` (bounded, trust-region
reflective); for each θ the linear ones (tares, drift rates, clogging torque gain, calibration
scales) are the weighted linear least-squares solution (variable projection, :func:`project`).
Residuals are weighted by the noise of each smoothed sample, so the cost is χ²/2.

Starting points: the pulsation frequency is multimodal, so a scan over frequencies (0.15–3.5
Hz) fits the exact linearisation of the pulsation term in (a, b) — load modulation plus depth
lead — together with linear stand-ins for the other mechanisms, one small linear solve per
frequency; its best local minima of χ² start separate fits. Softening's time constant is seeded by a
scan of the same kind. Each subset is also started from the best fit of its subsets with one
mechanism fewer; the best optimum is kept. The pulse-shaped and swept pulsations are fitted
only where the sine leaves more than noise (:func:`fit_all`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, signal
from scipy.linalg import lapack

from femstudy.diagnosis.mechanisms import MECHANISMS, Problem

FREQUENCY_GRID_HZ = np.geomspace(0.15, 3.5, 240)
TAU_GRID_S = np.geomspace(0.2, 40.0, 16)
NOMINAL_GROWTH = 0.5
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

    @property
    def pulse(self) -> bool:
        """The pulsation is pulse-shaped (its sharpness fitted)."""
        return "pulsation_sharpness" in self.variant


def _lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least squares for a few columns (tare, drift ramp, clogging torque): normal equations,
    or the SVD when a column is (nearly) zero, e.g. the clogging column at p = 0."""
    G = A.T @ A
    d = np.diag(G)
    if d.min() > 1e-10 * d.max():
        _, x, info = lapack.dposv(G, A.T @ b)  # Cholesky: a tenth of np.linalg.solve's overhead
        if info == 0:
            return x
    return np.linalg.lstsq(A, b, rcond=None)[0]


def project(problem: Problem, subset: frozenset, params: dict, rows: np.ndarray | None = None):
    """Whitened residuals on ``rows`` (default all) per channel, the linear parameters fitted
    there, and the smoothed model at all instants, for the nonlinear ``params``."""
    parts = problem.design(subset, params)
    names = problem.linear_names(subset)
    residuals, linear, model = [], {}, []
    for c, (base, A) in enumerate(parts):
        target = problem.whiten(c, problem.y[c] - base, rows)
        Aw = problem.whiten(c, A, rows)
        beta = _lstsq(Aw, target)
        if names[c][-1] == "torque_gain_Nmm_per_N" and beta[-1] < 0:  # k_T = R μ_w l_w / M ≥ 0
            beta = np.append(_lstsq(Aw[:, :-1], target), 0.0)
        linear.update(zip(names[c], beta))
        residuals.append(target - Aw @ beta)
        model.append(base + A @ beta)
    if "torque_gain_Nmm_per_N" in linear:  # per newton of recorded extra thrust, g_F·C
        linear["torque_gain_Nmm_per_N"] /= linear.get("thrust_N_scale", 1.0) or 1.0
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


def _pulsation_columns(problem: Problem, base_params: dict, freq: float) -> list[np.ndarray]:
    """d(model)/da and d(model)/db at a = b = 0, per channel (smoothed): load scaling plus the
    depth lead S'(τ)·δ."""
    t = problem.band.t_model
    sim = problem.simulation
    shift = base_params["shift_s"]
    t_contact = sim.contact_s + shift
    tau = t - shift
    w = 2 * math.pi * freq
    sin, cos = np.sin(w * t), np.cos(w * t)
    lead_a = (math.cos(w * t_contact) - cos) / w
    lead_b = (sin - math.sin(w * t_contact)) / w
    stop = (sim.contact_s + base_params["stop_depth_mm"] / problem.geometry.feed_mm_s
            if sim.stop_is_parameter else sim.stop_s)
    cutting = tau < stop
    cols = []
    F, T = sim.loads(tau, stop)
    for load in ([F] + ([T] if problem.has_torque else [])):
        slope = np.gradient(load, t)
        col_a = np.where(cutting, load * sin + slope * lead_a, 0.0)
        col_b = np.where(cutting, load * cos + slope * lead_b, 0.0)
        cols.append(problem.band.smooth_model(np.vstack([col_a, col_b])))
    return cols


def _stand_in_columns(problem: Problem, base_params: dict, tau_s: float) -> list[np.ndarray]:
    """Linear stand-ins per channel: the alignment's columns (scale, tare), a drift ramp,
    clogging at p = 0.5 and softening at τ_s."""
    terms = problem.terms({**base_params, "growth_exponent": NOMINAL_GROWTH})
    plain = problem.terms(base_params)
    t = problem.band.t_model
    t_contact = problem.simulation.contact_s + base_params["shift_s"]
    soft = -np.expm1(-np.maximum(t - t_contact, 0.0) / tau_s)
    aligned = problem.design(frozenset(), base_params)
    cols = []
    for c, (_, A) in zip(problem.channels, aligned):
        clog = terms["thrust_N"] - plain["thrust_N"] if c == "thrust_N" else terms.get("clog", 0 * t)
        smooth = problem.band.smooth_model(np.vstack([clog, plain[c] * soft]))
        cols.append(np.column_stack([A, problem.ramp, smooth[0], smooth[1]]))
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


def seeds(problem: Problem, base_params: dict) -> dict:
    """Starting values from linearised scans: pulsation frequencies (best few), a, b; softening
    time constant and fraction; growth exponent."""
    def frequencies():
        for f in FREQUENCY_GRID_HZ[FREQUENCY_GRID_HZ >= problem.lowest_pulsation_hz]:
            cols = _pulsation_columns(problem, base_params, f)
            yield f, [c.T for c in cols]

    scan = _scan(problem, base_params, frequencies, tau_s=2.0)
    chi2 = np.array([r[1] for r in scan])
    peaks = signal.argrelmin(np.concatenate([[np.inf], chi2, [np.inf]]))[0] - 1
    order = peaks[np.argsort(chi2[peaks])][:FREQUENCY_STARTS]
    pulsations = []
    for k in order:
        f, _, coef = scan[k]
        a, b = np.clip(coef[:2], -0.6, 0.6)
        pulsations.append({"pulsation_frequency_hz": float(f), "pulsation_a": float(a), "pulsation_b": float(b)})

    # softening time constant and growth exponent, with the best pulsation as a shared term
    best_f = pulsations[0]["pulsation_frequency_hz"] if pulsations else 1.0
    shared = [c.T for c in _pulsation_columns(problem, base_params, best_f)]
    by_tau = []
    for tau_s in TAU_GRID_S:
        (_, value, coef), = _scan(problem, base_params, lambda: [(tau_s, shared)], tau_s=tau_s)
        by_tau.append((value, tau_s, coef))
    _, tau_s, coef = min(by_tau, key=lambda r: r[0])
    n_aligned = len(problem.linear_names(frozenset())[0])
    thrust_coef = coef[2:2 + n_aligned + 3]  # after the two shared pulsation columns
    scale = thrust_coef[0] if problem.calibrate else 1.0
    clog_coef, soft_coef = thrust_coef[-2] / scale, thrust_coef[-1] / scale
    softening = {"softening_fraction": float(np.clip(-soft_coef, 0.02, 0.8)),
                 "softening_log10_tau_s": float(math.log10(tau_s))}
    g = problem.geometry
    z_max = max(g.cortex_mm - g.cone_mm, 0.0) / g.diameter_mm
    rise = max(clog_coef, 0.02) * math.expm1(NOMINAL_GROWTH * z_max) if z_max > 0 else 0.0
    growth = float(np.clip(math.log1p(rise) / z_max if z_max > 0 else NOMINAL_GROWTH, 0.02, 4.0))
    clogging = {"growth_exponent": growth, "clogging_onset_mm": 0.0, "clogging_retained": 0.5}
    return {"pulsations": pulsations, "softening": softening, "clogging": clogging}


def starting_points(subset: frozenset, base_params: dict, seed: dict, smaller: dict) -> list[dict]:
    """Starts for one subset: the seeds, and the best fit of a subset with one mechanism fewer
    completed by the seeds. Pulsation alone is started at every candidate frequency; larger
    subsets inherit the frequency through the smaller fits."""
    fixed = dict(base_params)
    if "chip_clogging" in subset:
        fixed.update(seed["clogging"])
    if "thermal_softening" in subset:
        fixed.update(seed["softening"])
    pulsations = seed["pulsations"] or [{"pulsation_a": 0.1, "pulsation_b": 0.0, "pulsation_frequency_hz": 1.0}]
    if "feed_pulsation" in subset:
        fixed.update(pulsations[0])
    starts = [fixed]
    if subset == {"feed_pulsation"}:
        starts += [{**fixed, **p} for p in pulsations[1:]]
    previous = [smaller[subset - {m}] for m in subset if subset - {m} in smaller]
    if previous:
        best = min(previous, key=lambda f: f.chi2_total)
        starts.append({**fixed, **best.params})
    return starts


def _variant_stage(problem: Problem, fits: dict, name: str, starts: tuple, fits_of=fit_each) -> None:
    """Refit the subsets with pulsation adding the optional parameter ``name``: first the best
    one, from each value in ``starts``; if it gains more than the parameter's BIC cost plus
    ``MIN_PULSE_GAIN`` there, every other one from the value found, kept where it gains as much.
    A subset that would stay behind the best one's refit even gaining twice as much
    (``REACH``) is left as it is: no selection can pick it (the all-mechanism subset, whose
    misfit scales the BIC, is always refitted)."""
    factor = problem.n_eff_factor
    cost = math.log(problem.y.size * factor) + MIN_PULSE_GAIN
    pulsed = sorted((s for s in fits if "feed_pulsation" in s), key=lambda s: fits[s].chi2_total)
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
    ``PULSE_GATE``), the pulsation's optional forms are tried (:func:`_variant_stage`): the
    pulse shape (sharpness κ, from 1.5 and 4), then a sweep of its frequency (r, from ±0.2),
    each on top of the subsets' forms so far."""
    allowed = [m for m in MECHANISMS if m != "chip_clogging" or problem.clogging_possible]
    subsets = [frozenset(m for k, m in enumerate(allowed) if mask >> k & 1) for mask in range(1 << len(allowed))]
    fits: dict = {}
    for size in range(len(allowed) + 1):
        level = [s for s in subsets if len(s) == size]
        requests = [(problem, s, starting_points(s, base_params, seed, fits), {}) for s in level]
        fits.update(zip(level, fits_of(requests)))
    full = fits[max(fits, key=len)]
    factor = problem.n_eff_factor
    if full.chi2_total * factor / max(problem.y.size * factor - full.n_params, 1.0) > PULSE_GATE:
        _variant_stage(problem, fits, "pulsation_sharpness", (1.5, 4.0), fits_of)
        _variant_stage(problem, fits, "pulsation_sweep", (-0.2, 0.2), fits_of)
    return fits
