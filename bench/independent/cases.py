"""Benchmark classes of the independent generator, their ground truth, and their files.

Every case is a recording (what a rig writes) and a simulation (what a model predicts for
the same pass) in the documented recording format, plus a ground truth: the set of
catalogue mechanisms the recording has and the simulation lacks, or — for a decoy — the
physics outside the catalogue and where it is.

==========================  =========================================================  ==============
class                       recording (beyond the nuisances below)                     truth
==========================  =========================================================  ==============
late_clogging               chip clogging that starts only after 0.5–2 mm of chip       chip_clogging
                            column (rise 20–60 % by breakthrough); simulation has none
too_little_clogging         clogging; the simulation has it too, with 25–55 % of the    chip_clogging
                            growth exponent
stick_slip                  sawtooth feed pulsation 8–30 % at 0.4–2.5 Hz                feed_pulsation
swept_pulsation             sine feed pulsation 8–30 % sweeping 0.3–1.2 → ×1.5–3 Hz     feed_pulsation
warmup_drift                exponential amplifier warm-up, 6–30 % of F_o over the        sensor_drift
                            recording (one case in four: a 4–6 N cut, 30 % drift)
hyperbolic_softening        cutting loads × 1 − s x/(1 + x), loss 10–30 % by the end    thermal_softening
clogging_and_warmup         late clogging and warm-up drift                             both
softening_and_stick_slip    softening and sawtooth pulsation                            both
complete                    nothing                                                     —
complete_clogging           clogging, in the simulation too                             —
chip_break_step  (decoy)    thrust and torque drop 12–20 % at one instant mid-cut       step
torque_friction  (decoy)    torque alone changes by ±12–30 % from one instant            torque-only
spindle_slowdown (decoy)    spindle speed N0/(1 + κT/T_o), 10–25 % slower at full load  spindle
feed_or_clock    (decoy)    true feed 8–15 % off the stated one, or a clock 3–8 % off   timing
thrust_wobble    (decoy)    thrust alone × 1 + 6–15 % sin(2πft), f 0.5–3 Hz             oscillation
hard_inclusion   (decoy)    a 0.4–1.2 mm layer in the cortex 25–50 % stronger           bump
==========================  =========================================================  ==============

Nuisances in every case: spindle 400–2000 rpm with a 1–8 % ripple and a second (two-flute)
harmonic, feed 0.5–2.5 mm/s at 0.03–0.15 mm/rev, drills of 2–4.5 mm with 90–118° points,
cortex 3–8 mm; four cases in five break through into cancellous bone and go 0.8–2.5 mm on,
one in five stop inside the cortex; white noise plus AR(1) (τ_c 20–300 ms) or 1/f noise in
most cases, quantisation (the thesis sensor's 1/80 N and 1/3200 N·m, or coarser), tare
offsets, 500–2000 Hz, torque written in N·mm or N·m. One named case in eight has no torque.
Simulations are exact apart from the missing physics, sampled at 100–500 Hz, half on the
recording's clock (their own span, possibly ending loaded at the feed stop), half timed
from first contact (t = 0 at contact), torque in N·mm or N·m, one in five without a header.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from bench.independent.physics import Clogging, History, Pass, Pulsation, history
from bench.independent.sensor import Sensor, record

NAMED = {
    "late_clogging": {"chip_clogging"},
    "too_little_clogging": {"chip_clogging"},
    "stick_slip": {"feed_pulsation"},
    "swept_pulsation": {"feed_pulsation"},
    "warmup_drift": {"sensor_drift"},
    "hyperbolic_softening": {"thermal_softening"},
    "clogging_and_warmup": {"chip_clogging", "sensor_drift"},
    "softening_and_stick_slip": {"thermal_softening", "feed_pulsation"},
    "complete": set(),
    "complete_clogging": set(),
}
DECOYS = {
    "chip_break_step": "step",
    "torque_friction": "torque_only",
    "spindle_slowdown": "spindle",
    "feed_or_clock": "timing",
    "thrust_wobble": "oscillation",
    "hard_inclusion": "bump",
}
CLASSES = list(NAMED) + list(DECOYS)


@dataclass(frozen=True)
class Case:
    name: str
    kind: str
    seed: int
    truth: frozenset[str]
    decoy: dict | None
    recording: Path
    simulation: Path
    events: dict
    parameters: dict

    def to_json(self) -> dict:
        return {"name": self.name, "class": self.kind, "seed": self.seed, "truth": sorted(self.truth),
                "decoy": self.decoy, "recording": self.recording.name, "simulation": self.simulation.name,
                "events": self.events, "parameters": self.parameters}


def _base_pass(rng: np.random.Generator, low_load: bool = False) -> Pass:
    diameter = float(rng.choice([2.0, 2.5, 2.7, 3.2, 3.5, 4.5]))
    angle = float(rng.choice([90.0, 100.0, 118.0]))
    rpm = float(np.round(rng.uniform(400, 2000), -1))
    a = rng.uniform(0.03, 0.15)
    feed = float(np.clip(a * rpm / 60, 0.5, 2.5))
    a = feed * 60 / rpm
    cone = diameter / 2 / math.tan(math.radians(angle / 2))
    cortex = float(rng.uniform(max(3.0, cone + 2.0), 8.0))
    thrust = rng.uniform(15, 35) * (a / 0.06) ** 0.8 * diameter / 2.7
    if low_load:
        thrust = rng.uniform(4, 6)
    torque = thrust * diameter / 2 * rng.uniform(0.35, 0.7)
    through = rng.random() < 0.8
    if through:
        stop = cortex + cone + rng.uniform(0.8, 2.5)
    else:
        lo = max(0.55 * cortex, cone + 1.2)
        stop = rng.uniform(lo, min(max(0.85 * cortex, lo + 0.3), cortex - 0.3))
    return Pass(feed_mm_s=round(feed, 3), spindle_rpm=rpm, diameter_mm=diameter, point_angle_deg=angle,
                cortex_mm=round(cortex, 3), thrust_N=float(thrust), torque_Nmm=float(torque),
                cancellous_ratio=float(rng.uniform(0.08, 0.3)), chisel_share=float(rng.uniform(0.08, 0.2)),
                approach_s=float(rng.uniform(1.0, 3.5)), stop_depth_mm=float(stop),
                dwell_s=float(rng.uniform(0.2, 1.0)), retract_mm_s=float(rng.uniform(3, 8)))


def _clogging(rng: np.random.Generator, p: Pass, rise: float, onset_mm: float) -> Clogging:
    """A clogging term whose thrust rise by breakthrough is ``rise`` × F_o."""
    gain = float(rng.uniform(0.6, 1.2))
    z = (p.cortex_mm - p.cone_mm - onset_mm) / p.diameter_mm
    exponent = math.log1p(rise / gain) / z
    return Clogging(exponent=exponent, gain=gain, onset_mm=onset_mm,
                    torque_per_thrust_mm=float(rng.uniform(0.3, 1.2)))


def _onset(rng: np.random.Generator, p: Pass) -> float:
    room = p.cortex_mm - p.cone_mm - 1.5
    return float(min(rng.uniform(0.5, 2.0), max(room, 0.0)))


def _sawtooth(rng: np.random.Generator) -> Pulsation:
    return Pulsation("sawtooth", float(rng.uniform(0.08, 0.3)), float(rng.uniform(0.4, 2.5)), 0.0,
                     float(rng.uniform(0, 2 * math.pi)))


def _duration(p: Pass) -> float:
    """Time to the end of the retraction, with an unloaded tail of 0.5–2.5 s added later."""
    cut = (p.stop_depth_mm + p.feed_mm_s * p.approach_s) / (p.feed_mm_s * min(p.feed_scale, 1.0) * 0.7)
    return p.approach_s + cut + p.dwell_s + (p.stop_depth_mm + 5) / p.retract_mm_s + 1


def _sensor(rng: np.random.Generator, p: Pass, torque_unit: str) -> Sensor:
    f_o, t_o = p.thrust_N, p.torque_Nmm
    coloured = str(rng.choice(["none", "ar1", "ar1", "pink", "pink"]))
    sigma = rng.uniform(0.005, 0.02)
    quantum_t = float(rng.choice([0.0, 1 / 80, 0.05]))
    if torque_unit == "Nm":
        quantum_q = float(rng.choice([0.0, 1 / 3200]))
    else:
        quantum_q = float(rng.choice([0.0, 0.1, 0.3125]))
    return Sensor(rate_hz=float(rng.choice([500.0, 1000.0, 1000.0, 2000.0])),
                  white=(float(rng.uniform(0.005, 0.03) * f_o), float(rng.uniform(0.005, 0.03) * t_o)),
                  ripple=(float(rng.uniform(0.01, 0.08)), float(rng.uniform(0.0, 0.04)),
                          float(rng.uniform(0, 6.28)), float(rng.uniform(0, 6.28))),
                  tare=(float(rng.uniform(-3, 3)), float(rng.uniform(-8, 8))),
                  coloured=coloured, coloured_sigma=(float(sigma * f_o), float(sigma * t_o)),
                  ar1_time_s=float(rng.uniform(0.02, 0.3)), quantum=(quantum_t, quantum_q),
                  torque_unit=torque_unit)


def _warmup(rng: np.random.Generator, p: Pass, duration: float, fraction: tuple[float, float]) -> tuple:
    """Warm-up drift whose change over the recording is ± ``fraction`` × F_o (and × T_o)."""
    tau = float(rng.uniform(4, 30))
    on = float(rng.uniform(0, 10))
    span = math.exp(-on / tau) - math.exp(-(on + duration) / tau)
    change_f = rng.choice([-1, 1]) * rng.uniform(*fraction) * p.thrust_N
    change_t = rng.choice([-1, 1]) * rng.uniform(*fraction) * p.torque_Nmm
    return (float(change_f / span), float(change_t / span), tau, on)


def _depth_time(h: History, depth: float) -> float:
    return float(h.time_s[int(np.argmax(h.depth_mm >= depth))])


def make_case(kind: str, seed: int, directory: Path) -> Case:
    """Draw one case of ``kind`` from ``seed`` and write its two files into ``directory``."""
    rng = np.random.default_rng(seed)
    low = kind == "warmup_drift" and seed % 4 == 1
    p = _base_pass(rng, low_load=low)
    truth = set(NAMED.get(kind, set()))
    sim_off: list[str] = []
    sim_pass = None
    decoy = None
    time_scale = 1.0
    warm = None
    if kind in ("late_clogging", "clogging_and_warmup"):
        p = replace(p, clogging=_clogging(rng, p, rng.uniform(0.2, 0.6), _onset(rng, p)))
        sim_off.append("clogging")
    elif kind in ("too_little_clogging", "complete_clogging"):
        p = replace(p, clogging=_clogging(rng, p, rng.uniform(0.4, 0.9), float(rng.choice([0.0, _onset(rng, p)]))))
        if kind == "too_little_clogging":
            c = p.clogging
            sim_pass = replace(p, clogging=replace(c, exponent=c.exponent * float(rng.uniform(0.25, 0.55))))
    elif rng.random() < 0.5:
        # half of the other cases cut with clogging that the simulation has too
        p = replace(p, clogging=_clogging(rng, p, rng.uniform(0.1, 0.5), 0.0))
    if kind in ("stick_slip", "softening_and_stick_slip"):
        p = replace(p, pulsation=_sawtooth(rng))
        sim_off.append("pulsation")
    if kind == "swept_pulsation":
        f1 = float(rng.uniform(0.3, 1.2))
        p = replace(p, pulsation=Pulsation("sweep", float(rng.uniform(0.08, 0.3)), f1,
                                           min(f1 * float(rng.uniform(1.5, 3.0)), 3.5), float(rng.uniform(0, 6.28))))
        sim_off.append("pulsation")
    if kind in ("hyperbolic_softening", "softening_and_stick_slip"):
        cut_s = p.stop_depth_mm / p.feed_mm_s
        loss = rng.uniform(0.1, 0.3)
        tau = float(rng.uniform(1, 6))
        x = cut_s / tau
        s = min(loss * (1 + x) / x, 0.6)
        p = replace(p, softening=(float(s), tau))
        sim_off.append("softening")
    duration = _duration(p)
    if kind in ("warmup_drift", "clogging_and_warmup"):
        warm = _warmup(rng, p, duration, (0.25, 0.35) if low else (0.06, 0.3))

    probe = history(p, duration)
    cut_from = probe.full_engagement_s
    cut_to = probe.breakthrough_s or probe.feed_stop_s
    if kind == "chip_break_step":
        # well inside the cut: a drop right at the stop would be the stop's own timing
        lo, hi = cut_from + 0.3 * (cut_to - cut_from), cut_to - max(0.15 * (cut_to - cut_from), 0.5)
        t_step = float(rng.uniform(lo, max(hi, lo + 0.05)))
        drop = float(rng.uniform(0.12, 0.2))
        p = replace(p, step=(t_step, drop))
        sim_off.append("step")
        decoy = {"kind": "step", "start_s": t_step, "end_s": probe.feed_stop_s, "channel": "both",
                 "drop": drop}
    elif kind == "torque_friction":
        t_on = float(rng.uniform(cut_from, cut_from + 0.6 * (cut_to - cut_from)))
        frac = float(rng.choice([-1, 1]) * rng.uniform(0.12, 0.3))
        p = replace(p, torque_change=(t_on, frac, float(rng.uniform(0.1, 1.0))))
        sim_off.append("torque_change")
        decoy = {"kind": "torque_only", "start_s": t_on, "end_s": probe.feed_stop_s, "channel": "torque",
                 "fraction": frac}
    elif kind == "spindle_slowdown":
        drop = float(rng.uniform(0.1, 0.25))
        p = replace(p, spindle_droop=drop / (1 - drop))
        sim_off.append("spindle_droop")
        decoy = {"kind": "spindle", "start_s": probe.contact_s, "end_s": probe.feed_stop_s, "channel": "both",
                 "speed_drop": drop}
    elif kind == "feed_or_clock":
        if rng.random() < 0.5:
            scale = float(rng.choice([-1, 1]) * rng.uniform(0.08, 0.15) + 1)
            p = replace(p, feed_scale=scale)
            sim_off.append("feed_scale")
            decoy = {"kind": "timing", "what": "feed", "scale": scale}
        else:
            time_scale = float(rng.choice([-1, 1]) * rng.uniform(0.03, 0.08) + 1)
            decoy = {"kind": "timing", "what": "clock", "scale": time_scale}
        decoy["channel"] = "both"
    elif kind == "thrust_wobble":
        hz = float(rng.uniform(0.5, 3.0))
        p = replace(p, thrust_wobble=(hz, float(rng.uniform(0.06, 0.15)), float(rng.uniform(0, 6.28))))
        sim_off.append("thrust_wobble")
        decoy = {"kind": "oscillation", "start_s": probe.contact_s, "end_s": probe.feed_stop_s,
                 "channel": "thrust", "frequency_hz": hz}
    elif kind == "hard_inclusion":
        deepest = min(p.cortex_mm, p.stop_depth_mm - p.cone_mm)
        y0 = float(rng.uniform(p.cone_mm + 0.3, max(deepest - 1.0, p.cone_mm + 0.4)))
        y1 = min(y0 + float(rng.uniform(0.4, 1.2)), deepest - 0.2)
        p = replace(p, inclusion=(y0, y1, float(rng.uniform(1.25, 1.5))))
        sim_off.append("inclusion")
        decoy = {"kind": "bump", "start_s": _depth_time(probe, y0), "end_s": _depth_time(probe, y1 + p.cone_mm),
                 "channel": "both"}
    h = history(p, duration)
    duration = h.retraction_end_s + float(rng.uniform(0.5, 2.5))
    h = history(p, duration)
    if kind == "feed_or_clock":
        decoy.update(start_s=h.contact_s * time_scale, end_s=h.feed_stop_s * time_scale)
    sim_pass = (sim_pass or p).without(*sim_off)
    hs = history(sim_pass, duration)

    torque = kind in ("torque_friction", "thrust_wobble") or rng.random() >= 0.125
    unit = "Nm" if rng.random() < 0.35 else "Nmm"
    sensor = _sensor(rng, p, unit)
    if warm is not None:
        sensor = replace(sensor, warmup=warm)
    rec = record(h, sensor, rng, duration, time_scale=time_scale)
    name = f"{kind}-{seed}"
    directory.mkdir(parents=True, exist_ok=True)
    rec_path = directory / f"{name}.csv"
    header = {"feed_mm_s": p.feed_mm_s, "spindle_rpm": p.spindle_rpm, "drill_diameter_mm": p.diameter_mm,
              "point_angle_deg": p.point_angle_deg}
    _write(rec_path, header | {"specimen": f"independent {kind}"}, rec["time_s"], rec["thrust_N"],
           rec["torque"] if torque else None, unit, time_fmt="%.7g")

    sim_path = directory / f"{name}-sim.csv"
    sim_clock = "contact" if rng.random() < 0.5 else "recording"
    sim_rate = float(rng.uniform(100, 500))
    if sim_clock == "contact":
        end = hs.feed_stop_s if rng.random() < 0.4 else hs.feed_stop_s + float(rng.uniform(0.3, 1.0))
        ts = np.arange(hs.contact_s, end, 1 / sim_rate)
        t_written = ts - hs.contact_s
    else:
        start = float(rng.uniform(0.2, max(hs.contact_s - 0.3, 0.3)))
        end = hs.feed_stop_s if rng.random() < 0.25 else float(rng.uniform(hs.retraction_end_s, duration))
        ts = np.arange(start, end, 1 / sim_rate)
        t_written = ts
    sim_unit = "Nm" if rng.random() < 0.3 else "Nmm"
    sim_torque = np.interp(ts, hs.time_s, hs.torque_Nmm) / (1000.0 if sim_unit == "Nm" else 1.0)
    _write(sim_path, header if rng.random() < 0.8 else None, t_written, np.interp(ts, hs.time_s, hs.thrust_N),
           sim_torque if torque else None, sim_unit, time_fmt="%.7g")

    events = {"contact_s": h.contact_s * time_scale, "full_engagement_s": h.full_engagement_s * time_scale,
              "breakthrough_s": None if h.breakthrough_s is None else h.breakthrough_s * time_scale,
              "exit_s": None if h.exit_s is None else h.exit_s * time_scale,
              "feed_stop_s": h.feed_stop_s * time_scale, "retraction_end_s": h.retraction_end_s * time_scale,
              "simulation_clock": sim_clock, "duration_s": duration * time_scale}
    params = {"feed_mm_s": p.feed_mm_s, "spindle_rpm": p.spindle_rpm, "diameter_mm": p.diameter_mm,
              "point_angle_deg": p.point_angle_deg, "cortex_mm": p.cortex_mm, "thrust_N": p.thrust_N,
              "torque_Nmm": p.torque_Nmm, "stop_depth_mm": p.stop_depth_mm,
              "clogging": None if p.clogging is None else vars(p.clogging),
              "simulated_clogging": None if sim_pass.clogging is None else vars(sim_pass.clogging),
              "softening": p.softening, "pulsation": None if p.pulsation is None else vars(p.pulsation),
              "warmup": warm, "sensor": {k: v for k, v in vars(sensor).items()},
              "torque_channel": torque, "torque_unit": unit, "simulation_unit": sim_unit,
              "simulation_rate_hz": sim_rate}
    case = Case(name, kind, seed, frozenset(truth), decoy, rec_path, sim_path, events, params)
    (directory / f"{name}.truth.json").write_text(json.dumps(case.to_json(), indent=1, default=float))
    return case


def _write(path: Path, header: dict | None, t, thrust, torque, unit: str, time_fmt: str) -> None:
    """Write the recording format: ``# key = value`` lines, then columns that name their unit."""
    lines = [f"# {k} = {json.dumps(v) if isinstance(v, str) else repr(float(v))}" for k, v in (header or {}).items()]
    columns = ["time_s", "thrust_N"] + ([f"torque_{unit}"] if torque is not None else [])
    data = np.column_stack([t, thrust] + ([torque] if torque is not None else []))
    fmt = [time_fmt, "%.6g"] + (["%.6g"] if torque is not None else [])
    with open(path, "w") as f:
        f.write("\n".join(lines + [",".join(columns)]) + "\n")
        np.savetxt(f, data, fmt=fmt, delimiter=",")


def make_cases(seed: int, per_class: int, directory: Path, kinds: list[str] | None = None) -> list[Case]:
    """``per_class`` cases of every class (or of ``kinds``), seeds seed·100000 + class·1000 + i."""
    out = []
    for k, kind in enumerate(CLASSES):
        if kinds and kind not in kinds:
            continue
        for i in range(per_class):
            out.append(make_case(kind, seed * 100_000 + k * 1000 + i, directory))
    return out
