"""The selected mechanisms in physical terms: parameters with units and a paragraph each.

Chip clogging's growth exponent is inverted for the flute friction with p = ηMD/S (Eq 3.13)
and M = μ_f (l_f + l_h + l_r) + l_w μ_f μ_w sin θ (Eq 3.14):

- with torque, the torque gain k_T = R μ_w l_w / M (Eq 3.19 over Eq 3.16's excess) gives μ_w,
  and then μ_f = M / (l_f + l_h + l_r + l_w μ_w sin θ): both from the recording;
- without torque, μ_w is taken from the bone set at the recording's feed and speed. The wall
  carries only about a sixth of M, so a 20 % error in that μ_w moves μ_f by about 3 %.

The inversion uses the total growth of the thrust, ln((S_F + C)/F_o)/z at breakthrough, so it
also holds when the simulation already had some clogging (then only μ_f is inverted, since
k_T is the torque of the missing part alone).
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.fit import Fit
from femstudy.diagnosis.mechanisms import Problem, feed_modulation
from femstudy.diagnosis.select import Selection, effect_sizes


def alignment(problem: Problem, fit: Fit) -> dict:
    """The nuisance parameters of the aligned simulation (not physics)."""
    out = {"shift_s": round(fit.params["shift_s"], 4)}
    if "stop_depth_mm" in fit.params:
        out["stop_depth_mm"] = round(fit.params["stop_depth_mm"], 3)
    for c in problem.channels:
        out[f"{c}_tare"] = round(fit.params[f"{c}_tare"], 4)
    return out


def calibration(problem: Problem, fit: Fit) -> dict:
    """The scale on each channel's simulated cutting load in the improved fit (1 = as simulated)."""
    return {f"{c}_scale": round(fit.params.get(f"{c}_scale", 1.0), 4) for c in problem.channels}


def _r(x, digits=4):
    return float(f"{x:.{digits}g}")


def clogging(problem: Problem, fit: Fit, bone_mu_w: float | None) -> tuple[dict, str]:
    """Growth, rise, torque gain and the friction they imply (see the module docstring)."""
    p, g, sim = fit.params, problem.geometry, problem.simulation
    drill = g.drill
    z_max = problem.clogging_span(p)
    growth = p["growth_exponent"]
    onset = p.get("clogging_onset_mm", 0.0)
    retained = p.get("clogging_retained")
    F_o = problem.initial_force_N * p.get("thrust_N_scale", 1.0)  # the recording's initial force
    excess = F_o * math.expm1(growth * z_max)
    simulated = float(sim.loads(np.array([sim.contact_s + g.cortex_mm / g.feed_mm_s]))[0][0])
    at_breakthrough = simulated * F_o / problem.initial_force_N
    own_growth = math.log(max(at_breakthrough, 1e-12) / F_o) / z_max if z_max > 0 else 0.0
    total = math.log(max(at_breakthrough + excess, 1e-12) / F_o) / z_max if z_max > 0 else growth
    M = total * drill.flute_area_mm2 / (drill.eta * drill.diameter_mm)
    sin_theta = math.sin(math.radians(drill.face_angle_deg))
    params = {"growth_exponent_per_diameter": _r(growth), "rise_at_breakthrough": _r(math.expm1(growth * z_max)),
              "excess_thrust_at_breakthrough_N": _r(excess), "initial_force_N": _r(F_o),
              "depth_past_full_engagement_diameters": _r(z_max), "total_growth_exponent": _r(total),
              "friction_factor_M_mm": _r(M), "onset_mm": _r(onset)}
    if retained is not None:
        params["retained_after_breakthrough"] = _r(retained)
    torque_text = ""
    gain = p.get("torque_gain_Nmm_per_N")
    mu_w, source = bone_mu_w, "the bone set at this feed and speed"
    if gain is not None:
        params["torque_gain_Nmm_per_N"] = _r(gain)
        torque_text = (f" The torque rises with it, by {gain:.3g} N·mm per newton of extra thrust "
                       f"({gain * excess:.3g} N·mm at breakthrough).")
        if abs(own_growth) < 0.01 and gain > 0:
            mu_w = gain * M / (drill.radius_mm * drill.wall_mm)
            source = "the torque gain k_T = R μ_w l_w / M"
    if mu_w is not None and M > 0:
        mu_f = M / (drill.flute_length_sum_mm + drill.wall_mm * mu_w * sin_theta)
        params["implied_mu_f"] = _r(mu_f)
        params["mu_w_used"] = _r(mu_w)
        params["mu_w_source"] = source
        friction_text = (f" Inverting p = ηMD/S (η = {drill.eta:g}, D = {drill.diameter_mm:g} mm, "
                         f"S = {drill.flute_area_mm2:g} mm²) gives M = {M:.3g} mm and, with μ_w = {mu_w:.3g} from "
                         f"{source}, an implied flute friction μ_f ≈ {mu_f:.3g}.")
    else:
        friction_text = ""
    text = (f"After full engagement the thrust rises above the simulation exponentially with depth: "
            f"F_o·(exp(p z) − 1) with p = {growth:.3g} per drill diameter of depth (F_o = {F_o:.3g} N), "
            f"{100 * math.expm1(growth * z_max):.0f} % (+{excess:.3g} N) by breakthrough, {z_max:.2f} diameters "
            f"past full engagement"
            f"{f' and an onset {onset:.2f} mm deeper' if onset > 0.05 else ''}"
            f"{f'; after breakthrough {100 * retained:.0f} % of it stays' if retained is not None else ''}."
            f"{torque_text} This is chip clogging: bone chips packing in the flutes "
            f"(thesis Eqs 3.16/3.19), missing from the simulation.{friction_text}")
    return params, text


def pulsation(problem: Problem, fit: Fit) -> tuple[dict, str]:
    """Amplitude, frequency, phase, waveform and the depth lead of the feed pulsation."""
    p, g = fit.params, problem.geometry
    A = math.hypot(p["pulsation_a"], p["pulsation_b"])
    f_p = p["pulsation_frequency_hz"]
    phase = math.atan2(p["pulsation_b"], p["pulsation_a"])
    t = np.linspace(0.0, 1.0 / f_p, 400)
    m, lead = feed_modulation({**p, "pulsation_sweep": 0.0}, t, 0.0)  # one period at f_p
    depth = g.feed_mm_s * np.ptp(lead) / 2
    kappa = p.get("pulsation_sharpness", 0.0)
    params = {"amplitude": _r(A), "frequency_hz": _r(f_p), "phase_rad": _r(phase), "period_s": _r(1 / f_p),
              "waveform": "pulse" if fit.pulse else "sine", "depth_amplitude_mm": _r(depth),
              "thrust_amplitude_N": _r(A * problem.initial_force_N * p.get("thrust_N_scale", 1.0))}
    sign = "−" if phase < -0.005 else "+"
    if fit.pulse:
        params["sharpness"] = _r(kappa)
        law = (f"f(t) = f·(1 + {A:.3g}·tanh({kappa:.2g}·sin(2π·{f_p:.3g}·t {sign} {abs(phase):.2f}))"
               f"/tanh({kappa:.2g})), fast and slow halves rather than a sine")
    else:
        law = f"f(t) = f·(1 + {A:.3g}·sin(2π·{f_p:.3g}·t {sign} {abs(phase):.2f}))"
    sweep = p.get("pulsation_sweep")
    if sweep is not None:
        rate = sweep * f_p / (problem.cut_s / 2)
        params["sweep_hz_per_s"] = _r(rate)
        params["frequency_at_s"] = _r(problem.sweep_centre_s + p["shift_s"])
        law += (f", its frequency drifting by {rate:+.3g} Hz/s (f_p = {f_p:.3g} Hz at "
                f"{problem.sweep_centre_s + p['shift_s']:.2f} s, {f_p * (1 - abs(sweep)):.3g}–"
                f"{f_p * (1 + abs(sweep)):.3g} Hz over the cut)")
    text = (f"The loads in contact oscillate at {f_p:.3g} Hz (period {1 / f_p:.3g} s) by ±{100 * A:.0f} % "
            f"(±{params['thrust_amplitude_N']:.3g} N of thrust at full engagement): the feed pulsates, {law}, so "
            f"the drill runs up to {1000 * depth:.0f} µm ahead of and behind the nominal depth. This is the "
            f"pulse-type feeding of a drive or slide that binds (thesis §4.5.3), not a property of the bone.")
    return params, text


def drift(problem: Problem, fit: Fit) -> tuple[dict, str]:
    """Drift rates and the change over the compared span, per channel."""
    p = fit.params
    span = float(problem.band.t_dec[-1] - problem.band.t_dec[0])
    rate_F = p["thrust_N_drift_per_s"]
    params = {"thrust_N_per_s": _r(rate_F), "thrust_change_N": _r(rate_F * span), "duration_s": _r(span)}
    parts = [f"the thrust reading drifts by {rate_F:+.3g} N/s ({rate_F * span:+.3g} N over {span:.1f} s)"]
    if "torque_Nmm_drift_per_s" in p:
        rate_T = p["torque_Nmm_drift_per_s"]
        params.update({"torque_Nmm_per_s": _r(rate_T), "torque_change_Nmm": _r(rate_T * span)})
        parts.append(f"the torque reading by {rate_T:+.3g} N·mm/s ({rate_T * span:+.3g} N·mm)")
    text = (f"The sensor zero moves steadily, in contact and out of it: {' and '.join(parts)}. The load-free "
            f"samples before contact and after retraction show it, which separates it from softening or "
            f"clogging. It is an instrument drift, not a cutting load; correct the recording for it before "
            f"calibrating.")
    return params, text


def softening(problem: Problem, fit: Fit) -> tuple[dict, str]:
    """Fraction, time constant and the loss reached by the end of the cut."""
    p = fit.params
    s, tau = p["softening_fraction"], 10 ** p["softening_log10_tau_s"]
    sim = problem.simulation
    cut = sim.stop_s - sim.contact_s if math.isfinite(sim.stop_s) else problem.band.t_dec[-1] - sim.contact_s
    if sim.stop_is_parameter:
        cut = fit.params["stop_depth_mm"] / problem.geometry.feed_mm_s
    loss = s * -math.expm1(-cut / tau)
    params = {"fraction": _r(s), "time_constant_s": _r(tau), "loss_at_end_of_cut": _r(loss),
              "time_in_contact_s": _r(cut)}
    text = (f"From contact on, the loads fall below the simulation by a fraction that grows as "
            f"{s:.3g}·(1 − exp(−t/{tau:.3g} s)); after {cut:.1f} s of cutting they are {100 * loss:.0f} % lower. "
            f"A loss that grows with time in contact, not with depth, is the bone softening as the cut heats it.")
    return params, text


EXPLAIN = {"chip_clogging": clogging, "feed_pulsation": pulsation, "sensor_drift": drift,
           "thermal_softening": softening}


def mechanisms(problem: Problem, fit: Fit, selection: Selection, verdict, bone_mu_w: float | None) -> list[dict]:
    """The contract's ``missing_physics`` entries for the named subset (``verdict.subset``),
    most confident first; confidence from the verdict (:mod:`.verdict`)."""
    out = []
    sizes = effect_sizes(problem, fit)
    subset = verdict.subset
    for m in sorted(subset, key=lambda m: -verdict.confidence[m]):
        args = (problem, fit, bone_mu_w) if m == "chip_clogging" else (problem, fit)
        params, text = EXPLAIN[m](*args)
        delta = selection.bic[subset - {m}] - selection.bic[subset]
        out.append({"mechanism": m, "confidence": verdict.confidence[m], "parameters": params,
                    "explanation": text, "evidence": {"delta_bic": round(delta, 1), "size": _r(sizes[m]),
                                                      "inclusion_probability": round(selection.confidence[m], 4)}})
    return out
