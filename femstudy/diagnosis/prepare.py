"""The diagnosis problem: the recording in the analysis band, the aligned simulation, the noise.

1. :func:`build_problem`: the window the simulation covers, the band (:mod:`.band`), the
   channels, a first (white) noise level from the spectrum above 10 Hz.
2. :func:`align`: the simulation as given, aligned robustly (clock shift, tares, a load
   model's stop depth).
3. :func:`with_noise`: the coloured noise model fitted on the aligned residual
   (:mod:`.noise`); from then on every residual is whitened by it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import optimize

from femstudy.diagnosis.band import STEP_SIGMAS, make_band, white_noise_sigma
from femstudy.diagnosis.fit import Fit
from femstudy.diagnosis.mechanisms import Geometry, Problem
from femstudy.diagnosis.noise import Whitener, fit_noise, smoothed_covariance
from femstudy.errors import require
from femstudy.recordings.reader import Recording

#: Fewest independent smoothed samples (steps of the band's decimation, STEP_SIGMAS Gaussian
#: widths) of a window that can be diagnosed.
MIN_INDEPENDENT = 10
#: Shifts tried before the alignment is refined [s].
SHIFT_GRID_S = np.arange(-0.45, 0.4501, 0.01)
#: A simulation that ends (starts) loaded is compared up to this long before its end (after its
#: start) [s]: its placement is not yet known to better than the alignment's range.
LOADED_EDGE_MARGIN_S = 0.25
#: A load model's stop is refined within ± this time [s] of the detected one.
STOP_SCAN_S = 0.3
#: Scale of the robust (Cauchy) alignment cost, in noise units.
CAUCHY_Z = 3.0
#: Fewest unloaded instants from which a tare is taken.
MIN_UNLOADED = 5
#: Smallest noise level, as a fraction of a channel's recorded range: a sensor resolves no
#: better, and below it the model's own quadrature error (about 1e-4 of the load) would count.
NOISE_FLOOR = 1e-3
#: Where the simulated thrust exceeds this fraction of its peak, the sample is loaded (not
#: used for the noise model).
LOADED_FRACTION = 1e-3


def build_problem(recording: Recording, simulation, cortex_mm: float) -> tuple[Problem, list]:
    """Smooth the recording in the window the simulation covers; estimate its noise."""
    notes = [simulation.note] if getattr(simulation, "note", "") else []
    t = recording.time_s
    lo, hi = simulation.span()
    start, end = max(t[0], lo + LOADED_EDGE_MARGIN_S), min(t[-1], hi - LOADED_EDGE_MARGIN_S)
    if start > t[0] or end < t[-1]:
        notes.append(f"compared over {start:.3f}-{end:.3f} s, where the simulation has loads on both sides")
    # a trace that starts loaded starts at its contact (its first sample), before the window
    reaches_contact = start <= simulation.contact_s <= end or not getattr(simulation, "zero_before", True)
    require(end - start > 1.0 and reaches_contact,
            f"the simulation (contact at {simulation.contact_s:.3f} s) does not overlap recording {recording.name} "
            f"({t[0]:.3f}-{t[-1]:.3f} s); it must cover the cut on the recording's clock")
    band = make_band(t, recording.spindle_rpm, start, end)
    independent = int((end - start) / (STEP_SIGMAS * band.sigma_s))
    require(independent >= MIN_INDEPENDENT, f"recording {recording.name} is too short to diagnose: {end - start:.2f} s "
                                            f"holds {independent} independent smoothed samples, need {MIN_INDEPENDENT}")
    channels = ["thrust_N"]
    if recording.torque_Nmm is not None and simulation.has_torque:
        channels.append("torque_Nmm")
    elif recording.torque_Nmm is not None:
        notes.append("the simulation has no torque: diagnosing on thrust alone")
    inside = (t >= start) & (t <= end)
    F_sim, T_sim = simulation.loads(t[inside])
    raw = {"thrust_N": recording.thrust_N, "torque_Nmm": recording.torque_Nmm}
    sims = {"thrust_N": F_sim, "torque_Nmm": T_sim}
    sigma_raw = np.array([white_noise_sigma(t[inside], raw[c][inside] - sims[c]) for c in channels])
    floor = NOISE_FLOOR * np.array([max(float(np.ptp(raw[c][inside])), 1e-9) for c in channels])
    sigma_raw = np.maximum(sigma_raw, floor)
    y = band.smooth(np.vstack([raw[c] for c in channels]))
    sigma = sigma_raw[:, None] * band.noise_gain[None, :]
    geometry = Geometry(recording.feed_mm_s, recording.spindle_rpm, recording.drill, cortex_mm)
    F_o = float(simulation.loads(np.array([simulation.contact_s + geometry.cone_mm / geometry.feed_mm_s]))[0][0])
    clogging_possible = cortex_mm > geometry.cone_mm + 0.05 * geometry.diameter_mm and F_o > 0
    if not clogging_possible:
        notes.append(f"the cortex ({cortex_mm:.2f} mm) is not thicker than the tip cone "
                     f"({geometry.cone_mm:.2f} mm): chip clogging cannot be tested")
    problem = Problem(band, tuple(channels), y, sigma, sigma_raw, simulation, geometry, F_o, clogging_possible)
    return problem, notes


def align(problem: Problem) -> Fit:
    """The simulation as given, aligned robustly: each channel's tare is the median of
    recording − simulation over the instants where the simulation is unloaded (all instants if
    fewer than ``MIN_UNLOADED``); the shift (and a load model's stop depth) minimise the Cauchy
    cost Σ ln(1 + (z/``CAUCHY_Z``)²), quadratic for small z and only logarithmic beyond, so
    stretches where physics is missing — however large — hardly drag the alignment, and the
    edges where the two agree (contact, breakthrough, stop) set it."""
    sim = problem.simulation

    def model(params):
        terms = problem.terms(params)
        base = problem.band.smooth_model(np.vstack([terms[c] for c in problem.channels]))
        unloaded = np.abs(base[0]) < 0.01 * max(float(np.max(np.abs(base[0]))), 1e-12)
        use = unloaded if np.count_nonzero(unloaded) >= MIN_UNLOADED else np.ones_like(unloaded)
        tare = np.median((problem.y - base)[:, use], axis=1)
        return base + tare[:, None], tare

    def cost(params):
        z = np.abs(problem.y - model(params)[0]) / problem.sigma
        return float(np.sum(np.log1p((z / CAUCHY_Z) ** 2)))

    params = {"shift_s": 0.0}
    if sim.stop_is_parameter:
        params["stop_depth_mm"] = sim.stop_depth_mm
        f = problem.geometry.feed_mm_s
        depths = sim.stop_depth_mm + f * np.arange(-STOP_SCAN_S, STOP_SCAN_S + 1e-9, 0.01)
    for _ in range(2 if sim.stop_is_parameter else 1):
        params["shift_s"] = min(SHIFT_GRID_S, key=lambda s: cost({**params, "shift_s": s}))
        if sim.stop_is_parameter:
            params["stop_depth_mm"] = min(depths, key=lambda d: cost({**params, "stop_depth_mm": d}))
    step = SHIFT_GRID_S[1] - SHIFT_GRID_S[0]
    best = optimize.minimize_scalar(lambda s: cost({**params, "shift_s": s}), method="bounded",
                                    bounds=(params["shift_s"] - step, params["shift_s"] + step),
                                    options={"xatol": 1e-4})
    params["shift_s"] = float(best.x)
    fitted, tare = model(params)
    params.update({f"{c}_tare": float(v) for c, v in zip(problem.channels, tare)})
    chi2 = np.sum(((problem.y - fitted) / problem.sigma) ** 2, axis=1)
    return Fit(frozenset(), params, chi2, fitted, len(problem.nonlinear_names(frozenset())) + len(problem.channels))


def with_noise(problem: Problem, baseline: Fit, recording: Recording) -> tuple[Problem, dict, list]:
    """The problem with its fitted noise model: the raw residual of the aligned simulation,
    AR models per channel (:func:`.noise.fit_noise`), their covariance at the analysis
    instants, and a whitener per channel. Returns the problem, the models by channel and notes."""
    t = recording.time_s
    band = problem.band
    inside = (t >= band.t_model[0]) & (t <= band.t_model[-1])
    predicted = problem.predict(baseline.params, t[inside])
    raw = {"thrust_N": recording.thrust_N, "torque_Nmm": recording.torque_Nmm}
    residuals = {c: raw[c][inside] - predicted[c] for c in problem.channels}
    load = problem.terms(baseline.params, t[inside])["thrust_N"]
    loaded = np.abs(load) > LOADED_FRACTION * max(float(np.max(np.abs(load))), 1e-12)
    fitted = fit_noise(t[inside], residuals, loaded, band.sigma_s)
    whiteners, sd = [], []
    for k, c in enumerate(problem.channels):
        cov = smoothed_covariance(fitted.models[c], band.t_dec, band.sigma_s, band.noise_gain)
        floor = (problem.sigma[k] ** 2)
        cov = cov + np.diag(np.maximum(floor - np.diag(cov), 0.0))  # never below the white level
        w = Whitener(cov)
        whiteners.append(w)
        sd.append(w.sd)
    return replace(problem, sigma=np.vstack(sd), noise=tuple(whiteners)), fitted.models, fitted.notes


def restate(problem: Problem, fit: Fit) -> Fit:
    """``fit`` with its χ² under the problem's (new) noise model."""
    chi2 = np.array([float(np.sum(problem.whiten(c, problem.y[c] - fit.model[c]) ** 2))
                     for c in range(len(problem.channels))])
    return Fit(fit.subset, fit.params, chi2, fit.model, fit.n_params, fit.variant)


def cut_window(problem: Problem, fit: Fit) -> np.ndarray:
    """Instants from contact to one revolution after the stop (the cutting phase)."""
    sim, t = problem.simulation, problem.band.t_dec
    shift = fit.params["shift_s"]
    stop = (sim.contact_s + fit.params["stop_depth_mm"] / problem.geometry.feed_mm_s
            if sim.stop_is_parameter else sim.stop_s)
    end = stop + shift + 60.0 / problem.geometry.spindle_rpm if math.isfinite(stop) else t[-1]
    return (t >= sim.contact_s + shift) & (t <= end)


