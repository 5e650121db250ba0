"""The diagnosis problem: the recording in the analysis band, the aligned simulation, the noise.

1. :func:`smoothed`: the window the simulation covers, the band (:mod:`.band`), the channels and a
   first (white) noise level from the spectrum above 10 Hz.
2. :func:`align`: the simulation as given, aligned robustly: clock shift (and a load model's
   stop depth) by a Cauchy cost, tares by medians over the unloaded instants.
3. :func:`in_air`: the events in the stretches where the drill is surely in air (:mod:`.air`),
   and what is left out of the fits.
4. :func:`with_noise`: the coloured noise model fitted there (:mod:`.noise`); from then on every
   residual is whitened by it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import optimize

from femstudy.diagnosis import air
from femstudy.diagnosis.band import INDEPENDENT_SIGMAS, make_band, white_noise_sigma
from femstudy.diagnosis.baseline import ModelSimulation
from femstudy.diagnosis.noise import NoiseSpectrum, Whitener, fit_noise, smoothed_covariance
from femstudy.diagnosis.problem import Geometry, Problem
from femstudy.errors import require
from femstudy.recordings.reader import Recording

#: Fewest independent smoothed samples (steps of INDEPENDENT_SIGMAS Gaussian widths) of a window.
MIN_INDEPENDENT = 10
#: Shifts tried before the alignment is refined [s].
SHIFT_GRID_S = np.arange(-0.45, 0.4501, 0.01)
#: A simulation that ends (starts) loaded is compared up to this long before its end (after its start) [s].
LOADED_EDGE_MARGIN_S = 0.25
#: A load model's stop is refined within ± this time [s] of the detected one.
STOP_SCAN_S = 0.3
#: Scale of the robust (Cauchy) alignment cost, in noise units.
CAUCHY_Z = 3.0
#: Fewest unloaded instants from which a tare is taken.
MIN_UNLOADED = 5
#: Smallest noise level, as a fraction of a channel's recorded range.
NOISE_FLOOR = 1e-3
#: Where the simulated thrust exceeds this fraction of its peak, the sample is loaded.
LOADED_FRACTION = 1e-3
#: An instant whose smoothing weight on left-out samples exceeds this is not used.
LEFT_OUT_WEIGHT = 0.01


def smoothed(recording: Recording, simulation, cortex_mm: float) -> tuple[Problem, list[str]]:
    """The recording smoothed in the window the simulation covers, with a white noise level."""
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
    independent = int((end - start) / (INDEPENDENT_SIGMAS * band.sigma_s))
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
    everywhere = np.ones(band.t_dec.size, bool)
    stop = simulation.stop_depth_mm if isinstance(simulation, ModelSimulation) else None
    problem = Problem(band, tuple(channels), y, sigma, sigma_raw, simulation, geometry, F_o, clogging_possible,
                      everywhere, ~everywhere, 0.0, stop)
    return problem, notes


@dataclass(frozen=True)
class Alignment:
    """The robust alignment: clock shift [s], a load model's stop depth [mm], the tares."""

    shift_s: float
    stop_depth_mm: float | None
    tares: np.ndarray


def _simulated(problem: Problem, shift: float, stop_depth: float | None) -> np.ndarray:
    sim = problem.simulation
    stop = sim.contact_s + stop_depth / problem.geometry.feed_mm_s if stop_depth is not None else sim.stop_s
    F, T = sim.loads(problem.band.t_model - shift, stop)
    return problem.band.smooth_model(np.vstack([F] + ([T] if problem.has_torque else [])))


def align(problem: Problem) -> Alignment:
    """The simulation as given, aligned robustly: each channel's tare is the median of recording −
    simulation over the unloaded instants; the shift (and a load model's stop depth) minimise the
    Cauchy cost Σ ln(1 + (z/``CAUCHY_Z``)²) of the residual less a straight line through its
    unloaded instants, so stretches where physics is missing hardly drag it, a drifting zero does
    not, and the edges where the two agree (contact, breakthrough, stop) set it."""

    t = problem.band.t_dec

    def unloaded(base):
        free = np.abs(base[0]) < 0.01 * max(float(np.max(np.abs(base[0]))), 1e-12)
        return free if np.count_nonzero(free) >= MIN_UNLOADED else np.ones_like(free)

    def model(shift, depth):
        base = _simulated(problem, shift, depth)
        tare = np.median((problem.y - base)[:, unloaded(base)], axis=1)
        return base + tare[:, None], tare

    def cost(shift, depth):
        """The Cauchy cost with the zero of each channel a straight line through the unloaded
        instants (a drifting sensor must not move the clock)."""
        base = _simulated(problem, shift, depth)
        free = unloaded(base)
        residual = problem.y - base
        line = np.vstack([np.polyval(np.polyfit(t[free], r[free], 1 if np.ptp(t[free]) > 0 else 0), t)
                          for r in residual])
        z = np.abs(residual - line)[:, problem.usable] / problem.sigma[:, problem.usable]
        return float(np.sum(np.log1p((z / CAUCHY_Z) ** 2)))

    shift, depth = 0.0, problem.stop_depth_mm
    depths = None
    if depth is not None:
        f = problem.geometry.feed_mm_s
        depths = depth + f * np.arange(-STOP_SCAN_S, STOP_SCAN_S + 1e-9, 0.01)
    for _ in range(2 if depth is not None else 1):
        shift = min(SHIFT_GRID_S, key=lambda s: cost(s, depth))
        if depths is not None:
            depth = float(min(depths, key=lambda d: cost(shift, d)))
    step = SHIFT_GRID_S[1] - SHIFT_GRID_S[0]
    best = optimize.minimize_scalar(lambda s: cost(s, depth), method="bounded", bounds=(shift - step, shift + step),
                                    options={"xatol": 1e-4})
    shift = float(best.x)
    return Alignment(shift, depth, model(shift, depth)[1])


def aligned(problem: Problem, alignment: Alignment) -> Problem:
    return replace(problem, shift_s=alignment.shift_s, stop_depth_mm=alignment.stop_depth_mm)


def _raw_model(problem: Problem, alignment: Alignment, t: np.ndarray) -> np.ndarray:
    sim = problem.simulation
    F, T = sim.loads(t - alignment.shift_s, problem.stop_s)
    loads = np.vstack([F] + ([T] if problem.has_torque else []))
    return loads + alignment.tares[:, None]


@dataclass(frozen=True)
class AirStretches:
    """The air events, and per raw sample: left out of the fits, surely in air (noise only)."""

    events: tuple[air.AirEvent, ...]
    left_out: np.ndarray
    quiet: np.ndarray


def in_air(problem: Problem, alignment: Alignment, recording: Recording, left_out: np.ndarray) -> AirStretches:
    """Events where the aligned simulation has the drill surely in air (:mod:`.air`)."""
    t = recording.time_s
    window = (t >= problem.band.t_model[0]) & (t <= problem.band.t_model[-1])
    F, _ = problem.simulation.loads(t[window] - alignment.shift_s, problem.stop_s)
    loaded = np.abs(F) > LOADED_FRACTION * max(float(np.max(np.abs(F))), 1e-12)
    raw = {"thrust_N": recording.thrust_N[window],
           "torque_Nmm": recording.torque_Nmm[window] if problem.has_torque else None}
    peaks = {c: problem.peak(k) for k, c in enumerate(problem.channels)}
    events, excluded, quiet = air.find(t[window], raw, loaded, peaks)
    left, calm = left_out.copy(), np.zeros(t.size, bool)
    left[window] |= excluded
    calm[window] = quiet
    return AirStretches(tuple(events), left, calm & ~left)


def with_noise(problem: Problem, alignment: Alignment, recording: Recording, stretches: AirStretches
               ) -> tuple[Problem, dict[str, NoiseSpectrum], tuple[str, ...]]:
    """The problem with its fitted noise model, the instants it uses and the ones surely in air."""
    t = recording.time_s
    band = problem.band
    inside = (t >= band.t_model[0]) & (t <= band.t_model[-1])
    predicted = _raw_model(problem, alignment, t[inside])
    raw = {"thrust_N": recording.thrust_N, "torque_Nmm": recording.torque_Nmm}
    residuals = {c: raw[c][inside] - predicted[k] for k, c in enumerate(problem.channels)}
    fitted = fit_noise(t[inside], residuals, stretches.quiet[inside], band.sigma_s)
    whiteners, sd = [], []
    for k, c in enumerate(problem.channels):
        cov = smoothed_covariance(fitted.models[c], band.t_dec, band.sigma_s, band.noise_gain)
        floor = problem.sigma[k] ** 2
        cov = cov + np.diag(np.maximum(floor - np.diag(cov), 0.0))  # never below the white level
        w = Whitener(cov)
        whiteners.append(w)
        sd.append(w.sd)
    weight_out = np.asarray(band.on_samples @ stretches.left_out.astype(float)).ravel()
    weight_air = np.asarray(band.on_samples @ stretches.quiet.astype(float)).ravel()
    usable = weight_out <= LEFT_OUT_WEIGHT
    quiet = (weight_air >= 1 - LEFT_OUT_WEIGHT) & usable
    out = replace(problem, sigma=np.vstack(sd), noise=tuple(whiteners), usable=usable, air=quiet,
                  shift_s=alignment.shift_s, stop_depth_mm=alignment.stop_depth_mm)
    return out, fitted.models, fitted.notes


def cut_window(problem: Problem, shift_s: float) -> np.ndarray:
    """Instants from contact to one revolution after the stop (the cutting phase)."""
    t = problem.band.t_dec
    stop = problem.stop_s
    end = stop + shift_s + problem.geometry.revolution_s if math.isfinite(stop) else t[-1]
    return (t >= problem.simulation.contact_s + shift_s) & (t <= end)
