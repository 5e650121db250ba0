"""Synthetic diagnosis cases: a recording with concealed missing physics and its simulation
(the fixtures of tests/test_diagnose.py and of bench/diagnose.py; not part of the package).

Each class draws its cutting conditions and effect sizes from the ranges below (a seeded
``numpy`` generator); the recording comes from :func:`femstudy.recordings.synthesize` with
noise and spindle ripple always on (nuisance, never "missing"), the simulation from the same
generator with every effect off, on its own sampling rate and time span. The truth is the set
of mechanisms the recording has and the simulation lacks.

=========================  ==================================================  ====================
class                      recording (beyond noise and ripple)                  simulation
=========================  ==================================================  ====================
clogging_under_pulsation   clogging rise 20–40 % by breakthrough, feed          Allotta
                           pulsation whose load swing exceeds the rise
clogging_hidden_by_drift   clogging rise 20–40 %, sensor drift of opposite      Allotta
                           sign cancelling 50–120 % of the rise
short_cortex               2–3 mm cortex, bone-set friction (rise 10–35 %)      Allotta
softening                  thermal softening 10–35 %, τ 0.5–5 s                 clogging
pulsation                  feed pulsation 5–40 % at 0.2–3 Hz                    clogging
drift                      drift ±0.03–0.3 N/s, ±0.1–1 N·mm/s                    clogging
softening_and_drift        both of the above                                    clogging
pulse_feed_clogging_       clogging rise 20–40 %, pulse-shaped feed pulsation   Allotta
softening                  10–40 % at 0.3–3 Hz, softening 10–35 %
complete                   nothing                                              the same model
=========================  ==================================================  ====================

Conditions: feed 0.8–2 mm/s, 1000–2000 rpm, cortex 4–7 mm (2–3 mm for short_cortex),
1–4 s before contact and after retraction, sampled at 500 or 1000 Hz; noise 0.2–1 N
(torque 3.3× in N·mm), ripple 2–8 %. The simulation is sampled at 200–1500 Hz and starts and
ends at other times than the recording (loads zero there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from femstudy.drilling import Drill
from femstudy.drilling.friction import builtin_bone_set
from femstudy.recordings import (Effects, FeedPulsation, Noise, Recording, SensorDrift, SpindleRipple,
                                 ThermalSoftening, synthesize)

CLASSES = {
    "clogging_under_pulsation": frozenset({"chip_clogging", "feed_pulsation"}),
    "clogging_hidden_by_drift": frozenset({"chip_clogging", "sensor_drift"}),
    "short_cortex": frozenset({"chip_clogging"}),
    "softening": frozenset({"thermal_softening"}),
    "pulsation": frozenset({"feed_pulsation"}),
    "drift": frozenset({"sensor_drift"}),
    "softening_and_drift": frozenset({"thermal_softening", "sensor_drift"}),
    "pulse_feed_clogging_softening": frozenset({"chip_clogging", "feed_pulsation", "thermal_softening"}),
    "complete": frozenset(),
}


@dataclass
class Case:
    """A recording, its simulation (recording format) and what the simulation lacks."""

    name: str
    kind: str
    recording: Recording
    simulation: Recording
    truth: frozenset
    simulation_model: str
    true: dict = field(default_factory=dict)   # true parameters of the missing mechanisms


def mu_f_for_growth(p: float, mu_w: float, drill: Drill = Drill()) -> float:
    """μ_f giving the growth exponent p at μ_w: p = ηMD/S, M = μ_f (l_f+l_h+l_r + l_w μ_w sin θ)."""
    M = p * drill.flute_area_mm2 / (drill.eta * drill.diameter_mm)
    return M / (drill.flute_length_sum_mm + drill.wall_mm * mu_w * math.sin(math.radians(drill.face_angle_deg)))


def make_case(kind: str, seed: int, torque: bool = True, duration_s: float | None = None) -> Case:
    """One random case of class ``kind`` (deterministic for a given seed); ``duration_s`` sets
    the recording's length at 1 kHz (the time before contact and after retraction shared equally)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform
    f, n = u(0.8, 2.0), u(1000, 2000)
    cortex = u(2.0, 3.0) if kind == "short_cortex" else u(4.0, 7.0)
    mu_f, mu_w = builtin_bone_set("bovine").friction(f, n)
    noise = u(0.2, 1.0)
    nuisance = dict(noise=Noise(noise, 3.3 * noise), ripple=SpindleRipple(u(0.02, 0.08)))
    effects = Effects(**nuisance, pulsation=None, drift=None, softening=None)
    drill, true = Drill(), {}
    z_max = (cortex - drill.cone_length_mm) / drill.diameter_mm
    sim_model = "clogging"
    if kind in ("clogging_under_pulsation", "clogging_hidden_by_drift", "pulse_feed_clogging_softening"):
        rise = u(0.2, 0.4)
        mu_f = mu_f_for_growth(math.log1p(rise) / z_max, mu_w, drill)
        sim_model = "allotta"
        true["rise"] = rise
    if kind == "short_cortex":
        sim_model = "allotta"
    if kind == "clogging_under_pulsation":
        effects = replace(effects, pulsation=FeedPulsation(u(true["rise"] + 0.05, min(true["rise"] + 0.25, 0.6)),
                                                           math.exp(u(math.log(0.3), math.log(3.0))),
                                                           u(0, 2 * math.pi)))
    if kind == "pulsation":
        effects = replace(effects, pulsation=FeedPulsation(u(0.05, 0.4), math.exp(u(math.log(0.2), math.log(3.0))),
                                                           u(0, 2 * math.pi)))
    if kind == "pulse_feed_clogging_softening":
        effects = replace(effects, pulsation=FeedPulsation(u(0.1, 0.4), math.exp(u(math.log(0.3), math.log(3.0))),
                                                           u(0, 2 * math.pi), "pulse"))
    if kind in ("softening", "softening_and_drift", "pulse_feed_clogging_softening"):
        effects = replace(effects, softening=ThermalSoftening(u(0.1, 0.35), math.exp(u(math.log(0.5), math.log(5.0)))))
    if kind in ("drift", "softening_and_drift"):
        effects = replace(effects, drift=SensorDrift(rng.choice([-1, 1]) * u(0.03, 0.3),
                                                     rng.choice([-1, 1]) * u(0.1, 1.0)))
    if kind == "complete":
        sim_model = str(rng.choice(["clogging", "allotta"]))
    rec_model = sim_model if kind == "complete" else "clogging"
    approach, tail = u(1.0, 4.0), u(1.0, 4.0)
    rate = float(rng.choice([500.0, 1000.0]))
    if duration_s is not None:
        approach = tail = (duration_s - (cortex + 2.0) / f) / 2
        rate = 1000.0
    common = dict(cortex_mm=cortex, mu_f=mu_f, mu_w=mu_w)
    if kind == "clogging_hidden_by_drift":
        clean = synthesize(f, n, **common, effects=Effects.none(), approach_s=approach, tail_s=tail)
        bare = synthesize(f, n, **common, model="allotta", effects=Effects.none(), approach_s=approach, tail_s=tail)
        t_bt = clean.metadata["true_breakthrough_s"] - clean.metadata["true_full_engagement_s"]
        at = clean.time_s <= clean.metadata["true_breakthrough_s"]
        dF = (clean.thrust_N - bare.thrust_N)[at][-1]
        dT = (clean.torque_Nmm - bare.torque_Nmm)[at][-1]
        effects = replace(effects, drift=SensorDrift(-u(0.5, 1.2) * dF / t_bt, -u(0.5, 1.2) * dT / t_bt))
    rec = synthesize(f, n, **common, model=rec_model, effects=effects, approach_s=approach, tail_s=tail,
                     sample_rate_hz=rate, seed=int(rng.integers(1 << 31)))
    if not torque:
        rec = replace(rec, torque_Nmm=None)
    sim_rate = float(rng.choice([200.0, 333.0, 1000.0, 1500.0]))
    sim_approach = u(0.3, approach)
    sim = synthesize(f, n, **common, model=sim_model, effects=Effects.none(), approach_s=sim_approach,
                     tail_s=u(0.3, tail), sample_rate_hz=sim_rate)
    sim = replace(sim, time_s=sim.time_s + (approach - sim_approach), source=f"<simulation of case {seed}>")
    m = rec.metadata
    if effects.pulsation and "feed_pulsation" in CLASSES[kind]:
        p = effects.pulsation
        true.update(amplitude=p.amplitude, frequency_hz=p.frequency_hz)
    if "chip_clogging" in CLASSES[kind]:
        true.update(growth_exponent=m["true_growth_exponent"], mu_f=m["true_mu_f"], mu_w=m["true_mu_w"])
    if effects.softening:
        sf, tau = effects.softening.fraction, effects.softening.time_constant_s
        in_contact = m["true_retraction_s"] - m["true_contact_s"]
        true.update(fraction=sf, time_constant_s=tau, loss_at_end_of_cut=sf * -math.expm1(-in_contact / tau))
    if effects.drift:
        true.update(thrust_N_per_s=effects.drift.thrust_N_per_s, torque_Nmm_per_s=effects.drift.torque_Nmm_per_s)
    rec = replace(rec, source=f"<{kind} case {seed}>")
    return Case(f"{kind}-{seed}", kind, rec, sim, CLASSES[kind], sim_model, true)
