"""Feed pulsation: the feed f(t) = f (1 + m(t)), m = a sin ωt + b cos ωt, ω = 2π f_p ≥ 2π/T_cut
(at least one period in the cut: slower is a feed-rate error), amplitude A = √(a² + b²), phase
atan2(b, a); or its pulse-shaped form of sharpness κ, or a sweep of its frequency by ±r of f_p
over half the cut (:func:`feed_modulation`). The drill runs ahead of the nominal depth by f δ(t),
δ = ∫_{contact}^{t} m dt, so the simulation is read at τ = t − Δt + δ(t), and the cutting
load, proportional to the feed per revolution, is scaled by P = 1 + m in contact. After the
feed stops δ is frozen and P = 1 (:class:`~.problem.Problem`).

Seeds: the frequency is multimodal, so a scan over frequencies (0.15–3.5 Hz) fits the exact
linearisation of the term in (a, b) — load modulation plus depth lead — with the other
mechanisms' stand-ins (:class:`..fit.Linearisation`); its best local minima start separate fits.
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.mechanisms.registry import Mechanism, Parameter, Scan, Variant, register, significant as _r

#: Frequencies of the seeds' scan [Hz].
FREQUENCY_GRID_HZ = np.geomspace(0.15, 3.5, 240)
#: Least amplitude (fraction of the feed) that counts as missing physics.
MIN_PULSATION_AMPLITUDE = 0.02
FREQUENCY_HZ = (0.15, 3.5)


def feed_modulation(params: dict, t: np.ndarray, t_contact: float, centre_s: float = 0.0,
                    half_span_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """m(t) and the depth lead δ(t) = ∫_{t_contact}^t m dt [s] of the feed pulsation.

    Sine: m = a sin φ + b cos φ with φ = ωt, δ in closed form. Swept (r ≠ 0): the frequency
    drifts through the cut, f_p (1 + r (t − centre_s)/half_span_s), i.e. φ = ωt + πk(t − centre_s)²
    with k = r f_p/half_span_s; |r| < 1 keeps it positive over the cut. Pulse (sharpness κ > 0, the generator's and a binding slide's fast
    and slow halves): m = A tanh(κ s/A)/tanh κ with s the sine above and A = √(a² + b²). The
    swept and pulse forms integrate δ by the trapezoid rule on ``t`` (which must resolve the
    period).
    """
    a, b = params["pulsation_a"], params["pulsation_b"]
    w = 2 * math.pi * params["pulsation_frequency_hz"]
    sweep = params.get("pulsation_sweep", 0.0) * params["pulsation_frequency_hz"] / half_span_s
    phase = w * t + (math.pi * sweep * (t - centre_s) ** 2 if sweep else 0.0)
    sin, cos = np.sin(phase), np.cos(phase)
    kappa = params.get("pulsation_sharpness", 0.0)
    amplitude = math.hypot(a, b)
    if (kappa < 1e-3 and not sweep) or amplitude == 0.0:
        s0, c0 = math.sin(w * t_contact), math.cos(w * t_contact)
        return a * sin + b * cos, (a * (c0 - cos) + b * (sin - s0)) / w
    m = a * sin + b * cos
    if kappa >= 1e-3:
        m = amplitude * np.tanh(kappa * m / amplitude) / math.tanh(kappa)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (m[1:] + m[:-1]) * np.diff(t))])
    return m, integral - np.interp(t_contact, t, integral)


def lowest_pulsation_hz(problem: Problem) -> float:
    """A feed pulsation completes at least one period in the cut; a slower change of the feed
    is a feed-rate error, not a pulsation [Hz]."""
    return min(max(FREQUENCY_HZ[0], 1.0 / problem.cut_s), 0.5 * FREQUENCY_HZ[1])


def sweep_centre_s(problem: Problem) -> float:
    """Where a swept pulsation's frequency is f_p: the middle of the cut [s] (simulation clock
    plus the alignment's few tens of milliseconds, which do not matter here)."""
    return problem.simulation.contact_s + problem.cut_s / 2


def feed(problem: Problem, params: dict, t: np.ndarray, t_contact: float) -> tuple[np.ndarray, np.ndarray]:
    return feed_modulation(params, t, t_contact, sweep_centre_s(problem), problem.cut_s / 2)


def scan_columns(problem: Problem, base_params: dict, freq: float) -> list[np.ndarray]:
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


def seeds(problem: Problem, linearisation) -> list[dict]:
    """One start per best local minimum of the frequency scan, amplitudes from its (a, b)."""
    out = []
    for f, _, coef in linearisation.scans["feed_pulsation"]:
        a, b = np.clip(coef[:2], -0.6, 0.6)
        out.append({"pulsation_frequency_hz": float(f), "pulsation_a": float(a), "pulsation_b": float(b)})
    return out or [{"pulsation_a": 0.1, "pulsation_b": 0.0, "pulsation_frequency_hz": 1.0}]


def size(problem: Problem, params: dict) -> float:
    """The amplitude A, a fraction of the feed."""
    return math.hypot(params["pulsation_a"], params["pulsation_b"])


def explain(problem: Problem, p: dict, bone_mu_w: float | None) -> tuple[dict, str]:
    """Amplitude, frequency, phase, waveform and the depth lead of the feed pulsation."""
    g = problem.geometry
    pulse = "pulsation_sharpness" in p
    A = math.hypot(p["pulsation_a"], p["pulsation_b"])
    f_p = p["pulsation_frequency_hz"]
    phase = math.atan2(p["pulsation_b"], p["pulsation_a"])
    t = np.linspace(0.0, 1.0 / f_p, 400)
    m, lead = feed_modulation({**p, "pulsation_sweep": 0.0}, t, 0.0)  # one period at f_p
    depth = g.feed_mm_s * np.ptp(lead) / 2
    kappa = p.get("pulsation_sharpness", 0.0)
    params = {"amplitude": _r(A), "frequency_hz": _r(f_p), "phase_rad": _r(phase), "period_s": _r(1 / f_p),
              "waveform": "pulse" if pulse else "sine", "depth_amplitude_mm": _r(depth),
              "thrust_amplitude_N": _r(A * problem.initial_force_N * p.get("thrust_N_scale", 1.0))}
    sign = "−" if phase < -0.005 else "+"
    if pulse:
        params["sharpness"] = _r(kappa)
        law = (f"f(t) = f·(1 + {A:.3g}·tanh({kappa:.2g}·sin(2π·{f_p:.3g}·t {sign} {abs(phase):.2f}))"
               f"/tanh({kappa:.2g})), fast and slow halves rather than a sine")
    else:
        law = f"f(t) = f·(1 + {A:.3g}·sin(2π·{f_p:.3g}·t {sign} {abs(phase):.2f}))"
    sweep = p.get("pulsation_sweep")
    if sweep is not None:
        rate = sweep * f_p / (problem.cut_s / 2)
        centre = sweep_centre_s(problem)
        params["sweep_hz_per_s"] = _r(rate)
        params["frequency_at_s"] = _r(centre + p["shift_s"])
        law += (f", its frequency drifting by {rate:+.3g} Hz/s (f_p = {f_p:.3g} Hz at "
                f"{centre + p['shift_s']:.2f} s, {f_p * (1 - abs(sweep)):.3g}–"
                f"{f_p * (1 + abs(sweep)):.3g} Hz over the cut)")
    text = (f"The loads in contact oscillate at {f_p:.3g} Hz (period {1 / f_p:.3g} s) by ±{100 * A:.0f} % "
            f"(±{params['thrust_amplitude_N']:.3g} N of thrust at full engagement): the feed pulsates, {law}, so "
            f"the drill runs up to {1000 * depth:.0f} µm ahead of and behind the nominal depth. This is the "
            f"pulse-type feeding of a drive or slide that binds (thesis §4.5.3), not a property of the bone.")
    return params, text


FEED_PULSATION = register(Mechanism(
    name="feed_pulsation",
    parameters=(Parameter("pulsation_a", -0.7, 0.7), Parameter("pulsation_b", -0.7, 0.7),
                Parameter("pulsation_frequency_hz", *FREQUENCY_HZ, lower_of=lowest_pulsation_hz),
                Parameter("pulsation_sharpness", 0.0, 5.0, optional=True),   # the pulse-shaped variant
                Parameter("pulsation_sweep", -0.7, 0.7, optional=True)),     # the swept variant
    seeds=seeds, size=size, threshold=MIN_PULSATION_AMPLITUDE, explain=explain, feed=feed,
    variants=(Variant("pulsation_sharpness", (1.5, 4.0)), Variant("pulsation_sweep", (-0.2, 0.2))),
    scan=Scan(grid=lambda problem: FREQUENCY_GRID_HZ[FREQUENCY_GRID_HZ >= lowest_pulsation_hz(problem)],
              columns=scan_columns, default=1.0)))
