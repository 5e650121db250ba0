"""Diagnose one recording against one simulation: locate, explain, model, show the improvement.

Steps (each in its module): the analysis band and the noise level (:mod:`.band`); the
alignment of the simulation (shift, tare, and the stop depth of a load model); the mismatch
intervals of the aligned simulation (:mod:`.locate`); fits of every subset of the four
mechanisms (:mod:`.fit`); selection (:mod:`.select`); the physical reading of the selected
parameters (:mod:`.explain`).

Calibration: when the selected model still leaves more than noise (χ² test p ≤ RESIDUAL_P),
everything is refitted with a scale on each channel's simulated cutting load (a simulation
whose cutting energy is off by a few percent is otherwise "explained" by softening or
clogging). The rescaled family is kept when its selected model has a BIC lower by
MIN_DELTA_BIC, on the data's own noise level. The scale is not admitted from the start
because it makes slow softening and clogging nearly interchangeable (both are close to
linear in time over a cut, and the scale removes the anchor the initial force provides).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import optimize

from femstudy.diagnosis import explain
from femstudy.diagnosis.band import make_band, white_noise_sigma
from femstudy.diagnosis.baseline import ModelSimulation, TraceSimulation
from femstudy.diagnosis.fit import Fit, fit_all, fit_subset, seeds
from femstudy.diagnosis.locate import mismatch_intervals
from femstudy.diagnosis.mechanisms import Geometry, Problem
from femstudy.diagnosis.select import MIN_DELTA_BIC, RESIDUAL_P, Selection, select
from femstudy.drilling.friction import BoneSet, load_bone_set
from femstudy.errors import require
from femstudy.recordings.reader import Recording

#: Shifts tried before the alignment is refined [s].
SHIFT_GRID_S = np.arange(-0.3, 0.3001, 0.01)
#: A load model's stop is refined within ± this time [s] of the detected one.
STOP_SCAN_S = 0.3
#: Huber threshold of the robust alignment, in noise units.
HUBER_Z = 3.0
#: Fewest unloaded instants from which a tare is taken.
MIN_UNLOADED = 5
#: Smallest noise level, as a fraction of a channel's recorded range: a sensor resolves no
#: better, and below it the model's own quadrature error (about 1e-4 of the load) would count.
NOISE_FLOOR = 1e-3


@dataclass
class Diagnosis:
    """Everything the command reports."""

    recording: Recording
    problem: Problem
    baseline: Fit
    fits: dict
    selection: Selection
    mismatch: list
    mechanisms: list             # dicts: mechanism, confidence, parameters, explanation
    fit_summary: dict            # per channel: baseline/improved r2, rmse
    seconds: float
    notes: list = field(default_factory=list)

    @property
    def improved(self) -> Fit:
        return self.fits[self.selection.subset]

    def to_json(self) -> dict:
        """The issue's JSON contract, with per-channel and selection detail added."""
        thrust = self.fit_summary["thrust_N"]
        return {
            "mismatch": self.mismatch,
            "missing_physics": self.mechanisms,
            "fit": {"baseline": thrust["baseline"], "improved": thrust["improved"],
                    "window_s": thrust["window_s"],
                    "channels": {c: {k: v for k, v in s.items() if k != "window_s"}
                                 for c, s in self.fit_summary.items()}},
            "alignment": explain.alignment(self.problem, self.baseline),
            "calibration": explain.calibration(self.problem, self.improved),
            "noise": {c: float(s) for c, s in zip(self.problem.channels, self.problem.sigma_raw)},
            "residual_check": {"chi2_per_dof": round(self.selection.chi2_per_dof, 3),
                               "p_value": self.selection.residual_p_value,
                               "consistent_with_noise": bool(self.selection.residual_p_value > RESIDUAL_P)},
            "selection": {"bic": {"+".join(sorted(s)) or "none": round(b, 2)
                                  for s, b in sorted(self.selection.bic.items(), key=lambda kv: kv[1])},
                          "not_selected": self.selection.dropped,
                          "confidence": {m: round(c, 4) for m, c in self.selection.confidence.items()}},
            "seconds": round(self.seconds, 3),
            "notes": self.notes,
        }


def build_problem(recording: Recording, simulation, cortex_mm: float) -> tuple[Problem, list]:
    """Smooth the recording in the window the simulation covers; estimate its noise."""
    notes = [simulation.note] if getattr(simulation, "note", "") else []
    t = recording.time_s
    lo, hi = simulation.span()
    start, end = max(t[0], lo), min(t[-1], hi)
    if start > t[0] or end < t[-1]:
        notes.append(f"compared over {start:.3f}-{end:.3f} s, where the simulation has loads on both sides")
    require(end - start > 1.0 and start <= simulation.contact_s <= end,
            f"the simulation (contact at {simulation.contact_s:.3f} s) does not overlap recording {recording.name} "
            f"({t[0]:.3f}-{t[-1]:.3f} s); it must cover the cut on the recording's clock")
    band = make_band(t, recording.spindle_rpm, start, end)
    require(band.t_dec.size >= 20, f"recording {recording.name} is too short to diagnose: "
                                   f"{end - start:.2f} s gives {band.t_dec.size} smoothed samples, need 20")
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
    fewer than ``MIN_UNLOADED``); the shift (and a load model's stop depth) minimise the Huber
    cost Σ ρ(z), ρ quadratic up to |z| = ``HUBER_Z`` and linear beyond, so stretches where
    physics is missing do not drag the alignment."""
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
        return float(np.sum(np.where(z <= HUBER_Z, 0.5 * z * z, HUBER_Z * z - 0.5 * HUBER_Z ** 2)))

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


def _cut_window(problem: Problem, fit: Fit) -> np.ndarray:
    """Instants from contact to one revolution after the stop (the cutting phase)."""
    sim, t = problem.simulation, problem.band.t_dec
    shift = fit.params["shift_s"]
    stop = (sim.contact_s + fit.params["stop_depth_mm"] / problem.geometry.feed_mm_s
            if sim.stop_is_parameter else sim.stop_s)
    end = stop + shift + 60.0 / problem.geometry.spindle_rpm if math.isfinite(stop) else t[-1]
    return (t >= sim.contact_s + shift) & (t <= end)


def summarise_fit(problem: Problem, baseline: Fit, improved: Fit) -> dict:
    """R² and RMSE of the smoothed recording over the cutting phase, per channel."""
    window = _cut_window(problem, baseline)
    if np.count_nonzero(window) < 3:
        window = np.ones_like(window)
    out = {}
    t = problem.band.t_dec[window]
    for c, name in enumerate(problem.channels):
        y = problem.y[c, window]
        scores = {}
        for label, fit in (("baseline", baseline), ("improved", improved)):
            r = y - fit.model[c, window]
            scores[label] = {"r2": round(float(1 - np.sum(r ** 2) / np.sum((y - y.mean()) ** 2)), 4),
                             "rmse": round(float(np.sqrt(np.mean(r ** 2))), 4)}
        out[name] = {**scores, "window_s": [round(float(t[0]), 3), round(float(t[-1]), 3)]}
    return out


def fit_and_select(problem: Problem, start_params: dict) -> tuple[dict, Selection]:
    """Every subset fitted from the seeds and the aligned parameters, then selected."""
    fits = fit_all(problem, start_params, seeds(problem, start_params))
    return fits, select(problem, fits)


def plain_bic(problem: Problem, fit: Fit) -> float:
    """BIC on the data's own noise level (no misfit inflation), comparable across calibrations."""
    n_eff = problem.y.size * problem.band.n_eff_factor
    return fit.chi2_total * problem.band.n_eff_factor + fit.n_params * math.log(n_eff)


def diagnose(recording: Recording, simulation: TraceSimulation | ModelSimulation, cortex_mm: float,
             bone: str | BoneSet = "bovine", progress=None) -> Diagnosis:
    """Diagnose ``recording`` against ``simulation`` (see the module docstring). ``bone`` gives
    μ_w for the friction reading of chip clogging when the torque cannot."""
    start = time.perf_counter()
    say = progress or (lambda message: None)
    problem, notes = build_problem(recording, simulation, cortex_mm)
    say(f"{problem.band.t_dec.size} smoothed samples per channel ({', '.join(problem.channels)}), "
        f"noise {', '.join(f'{s:.3g}' for s in problem.sigma_raw)}")
    baseline = align(problem)
    z = (problem.y - baseline.model) / problem.sigma
    mismatch = sorted((interval for c, name in enumerate(problem.channels)
                       for interval in mismatch_intervals(problem.band.t_dec, z[c], problem.band.n_eff_factor, name)),
                      key=lambda i: (i["start_s"], i["channel"]))
    say(f"aligned (shift {baseline.params['shift_s'] * 1e3:+.0f} ms); {len(mismatch)} mismatch interval(s)")
    start_params = {k: baseline.params[k] for k in problem.nonlinear_names(frozenset())}
    fits, selection = fit_and_select(problem, start_params)
    say(f"fitted {len(fits)} mechanism subsets")
    if selection.residual_p_value <= RESIDUAL_P:
        scaled = replace(problem, calibrate=True)
        scaled_fits, scaled_selection = fit_and_select(scaled, start_params)
        if (plain_bic(scaled, scaled_fits[scaled_selection.subset])
                < plain_bic(problem, fits[selection.subset]) - MIN_DELTA_BIC):
            problem, fits, selection = scaled, scaled_fits, scaled_selection
        say(f"refitted with the simulated loads rescaled: {'kept' if problem.calibrate else 'not better'}")
    improved = fits[selection.subset]
    bone_set = load_bone_set(bone) if isinstance(bone, str) else bone
    bone_mu_w = bone_set.friction(recording.feed_mm_s, recording.spindle_rpm)[1]
    mechanisms = explain.mechanisms(problem, improved, selection, bone_mu_w)
    summary = summarise_fit(problem, baseline, improved)
    return Diagnosis(recording, problem, baseline, fits, selection, mismatch, mechanisms, summary,
                     time.perf_counter() - start, notes)
