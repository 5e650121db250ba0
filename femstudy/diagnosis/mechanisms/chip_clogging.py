"""Chip clogging (Eqs 3.16/3.19, as in :mod:`femstudy.drilling.history`, generalised).

C = F_o (exp(p z) − 1) w(d), z = max(min(d, h) − l − L0, 0)/D the chip column past full
engagement and an onset L0 ≥ 0, in diameters (frozen at breakthrough); w(d) the share s(d) of
the tip cone still in cortex, and after breakthrough s + ρ(1 − s): a fraction ρ of the chips
stays packed in the cortical hole. F_o is the simulated thrust at full engagement. The torque
gains k_T C with k_T = R μ_w l_w / M ≥ 0. Fitted: p ≥ 0, L0, ρ ∈ [0, 1] (when the simulation
breaks through) and, with torque, k_T. L0 = 0 and ρ = 0 is the thesis's form.

The explanation inverts the growth exponent for the flute friction with p = ηMD/S (Eq 3.13)
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

from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.mechanisms.registry import Mechanism, Parameter, register, significant as _r

#: The growth exponent of the linear stand-in and the seed's fallback [1/diameter].
NOMINAL_GROWTH = 0.5
#: Least clogging rise by breakthrough (fraction of the load) that counts as missing physics.
MIN_CLOGGING_RISE = 0.05


def clogging_span(problem: Problem, params: dict) -> float:
    """z at breakthrough: the chip column past full engagement and the onset, in diameters."""
    g = problem.geometry
    return max(g.cortex_mm - g.cone_mm - params.get("clogging_onset_mm", 0.0), 0.0) / g.diameter_mm


def onset_room(problem: Problem) -> float:
    """Upper bound of the onset: most of the chip column before breakthrough [mm]."""
    return max(0.8 * (problem.geometry.cortex_mm - problem.geometry.cone_mm), 0.05)


def excess(problem: Problem, params: dict, tau: np.ndarray, stop: float) -> np.ndarray:
    """C(τ) [N]: the extra thrust of the packed chips (the module docstring)."""
    g = problem.geometry
    d = g.feed_mm_s * np.clip(np.minimum(tau, stop) - problem.simulation.contact_s, 0.0, None)
    inside = np.minimum(d, g.cortex_mm)
    z = np.maximum(inside - g.cone_mm - params.get("clogging_onset_mm", 0.0), 0.0) / g.diameter_mm
    share = np.clip(inside - np.maximum(d - g.cone_mm, 0.0), 0.0, g.cone_mm) / g.cone_mm
    if "clogging_retained" in params:  # chips still packed in the cortical hole after breakthrough
        share = np.where(d > g.cortex_mm, share + params["clogging_retained"] * (1.0 - share), share)
    fall = np.clip(1.0 - (tau - stop) * g.spindle_rpm / 60.0, 0.0, 1.0) if math.isfinite(stop) else 1.0
    return problem.initial_force_N * np.expm1(params["growth_exponent"] * z) * share * fall


def stand_in(problem: Problem, base_params: dict, plain: dict, tau_s: float) -> dict:
    """Linear stand-in per channel: the extra loads at the nominal growth exponent."""
    terms = problem.terms({**base_params, "growth_exponent": NOMINAL_GROWTH})
    out = {"thrust_N": terms["thrust_N"] - plain["thrust_N"]}
    if problem.has_torque:
        out["torque_Nmm"] = terms["excess"]["chip_clogging"]
    return out


def seeds(problem: Problem, linearisation) -> list[dict]:
    """The growth exponent that gives the stand-in's fitted rise by breakthrough."""
    g = problem.geometry
    z_max = max(g.cortex_mm - g.cone_mm, 0.0) / g.diameter_mm
    coef = linearisation.stand_ins["chip_clogging"]
    rise = max(coef, 0.02) * math.expm1(NOMINAL_GROWTH * z_max) if z_max > 0 else 0.0
    growth = float(np.clip(math.log1p(rise) / z_max if z_max > 0 else NOMINAL_GROWTH, 0.02, 4.0))
    return [{"growth_exponent": growth, "clogging_onset_mm": 0.0, "clogging_retained": 0.5}]


def size(problem: Problem, params: dict) -> float:
    """The rise by breakthrough, a fraction of the load."""
    return math.expm1(params["growth_exponent"] * clogging_span(problem, params))


def explain(problem: Problem, p: dict, bone_mu_w: float | None) -> tuple[dict, str]:
    """Growth, rise, torque gain and the friction they imply (see the module docstring)."""
    g, sim = problem.geometry, problem.simulation
    drill = g.drill
    z_max = clogging_span(problem, p)
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


CHIP_CLOGGING = register(Mechanism(
    name="chip_clogging",
    parameters=(Parameter("growth_exponent", 0.0, 5.0),
                Parameter("clogging_onset_mm", 0.0, None, upper_of=onset_room),
                Parameter("clogging_retained", 0.0, 1.0, needs=lambda problem: problem.breaks_through,
                          held_out_fixed=True)),
    seeds=seeds, size=size, threshold=MIN_CLOGGING_RISE, explain=explain,
    excess=excess, torque_gain="torque_gain_Nmm_per_N", stand_in=stand_in,
    possible=lambda problem: problem.clogging_possible))
