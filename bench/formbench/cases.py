"""Classes of the form-randomised benchmark, how a case is drawn, and its two files.

A case is a recording (as a rig's logger writes it: :mod:`.hardware`) and a simulation of the
same pass without the missing physics (clean, at 100–1000 Hz, on the recording's clock or timed
from contact, with or without a header, 0–3 % off in its cutting energy one time in four), plus
the truth: the catalogue mechanisms the recording has and the simulation lacks, or the decoy
(:mod:`.decoys`) and where it acts. Every mechanism is drawn from the forms of one split
(:data:`.forms.TUNING` or :data:`.forms.HELD_OUT`), and every decoy from that split's decoys.

======================================  =============================================  ==========
class                                   recording, beyond the nuisances                 truth
======================================  =============================================  ==========
clogging, pulsation, drift, softening   one mechanism                                  it
clogging+drift, clogging+pulsation,     two mechanisms                                 both
softening+pulsation, softening+drift,
clogging+softening, drift+pulsation
clogging+softening+pulsation            three                                          all three
too_little_clogging                     clogging; the simulation has 25–55 % of it      clogging
complete                                nothing                                         —
complete_clogging                       clogging, which the simulation has too          —
decoy:<kind>                            one decoy                                       none named
======================================  =============================================  ==========

Nuisances: drill 2–4.5 mm with a 90–135° point, 600–2500 rpm, 0.03–0.15 mm/rev (0.5–2.5 mm/s;
one case in seven a slow exit at 1–1.25 mm/s and 800–1000 rpm), cortex 2.5–8 mm, four cases in
five breaking through into cancellous bone; Kienzle exponent 0.15–0.4 and a lag of 0.2–0.7
revolution; clogging that the simulation has too in two of five cases without missing clogging;
the acquisition chain of :mod:`.hardware`; torque in N·mm or N·m, and no torque in one named case
in eight; a quarter of the cases 20 s long at 1 kHz.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from bench.formbench import decoys as decoy_shapes
from bench.formbench.drilling import Pass, cut
from bench.formbench.forms import (HELD_OUT, HELD_OUT_DECOYS, TUNING, TUNING_DECOYS, draw_clogging, draw_drift,
                                   draw_pulsation, draw_softening)
from bench.formbench.hardware import acquire, draw_hardware

NAMED = {
    "clogging": {"chip_clogging"}, "pulsation": {"feed_pulsation"}, "drift": {"sensor_drift"},
    "softening": {"thermal_softening"},
    "clogging+drift": {"chip_clogging", "sensor_drift"}, "clogging+pulsation": {"chip_clogging", "feed_pulsation"},
    "softening+pulsation": {"thermal_softening", "feed_pulsation"},
    "softening+drift": {"thermal_softening", "sensor_drift"},
    "clogging+softening": {"chip_clogging", "thermal_softening"},
    "drift+pulsation": {"sensor_drift", "feed_pulsation"},
    "clogging+softening+pulsation": {"chip_clogging", "thermal_softening", "feed_pulsation"},
    "too_little_clogging": {"chip_clogging"},
    "complete": set(), "complete_clogging": set(),
}
#: Cases per class in a standard run (decoys: per decoy kind).
PER_CLASS = {"clogging": 6, "pulsation": 6, "drift": 6, "softening": 6, "clogging+softening+pulsation": 4,
             "too_little_clogging": 4, "complete": 6, "complete_clogging": 4}
PAIRS_PER_CLASS = 4
DECOYS_PER_KIND = 4


@dataclass(frozen=True)
class Case:
    name: str
    kind: str
    split: str
    seed: int
    truth: frozenset
    forms: dict
    decoy: dict | None
    recording: Path
    simulation: Path
    long: bool
    parameters: dict

    def to_json(self) -> dict:
        return {"name": self.name, "class": self.kind, "split": self.split, "seed": self.seed,
                "truth": sorted(self.truth), "forms": self.forms, "decoy": self.decoy,
                "recording": self.recording.name, "simulation": self.simulation.name, "long": self.long,
                "parameters": self.parameters}


def classes(split: str) -> list[str]:
    """The classes of a run on ``split`` ("tuning" or "held_out")."""
    kinds = TUNING_DECOYS if split == "tuning" else HELD_OUT_DECOYS
    return list(NAMED) + [f"decoy:{k}" for k in kinds]


def per_class(kind: str) -> int:
    if kind.startswith("decoy:"):
        return DECOYS_PER_KIND
    return PER_CLASS.get(kind, PAIRS_PER_CLASS)


def _pass(rng: np.random.Generator, long: bool) -> Pass:
    diameter = float(rng.choice([2.0, 2.5, 2.7, 3.2, 3.5, 4.0, 4.5]))
    angle = float(rng.choice([90.0, 100.0, 118.0, 120.0, 135.0]))
    if rng.random() < 1 / 7:   # a slow exit
        feed, rpm = float(rng.uniform(1.0, 1.25)), float(np.round(rng.uniform(800, 1000), -1))
    else:
        rpm = float(np.round(rng.uniform(600, 2500), -1))
        feed = float(np.clip(rng.uniform(0.03, 0.15) * rpm / 60, 0.5, 2.5))
    cone = diameter / 2 / math.tan(math.radians(angle / 2))
    cortex = float(rng.uniform(max(2.5, cone + 1.5), 8.0))
    a = feed * 60 / rpm
    thrust = float(rng.uniform(12, 40) * (a / 0.06) ** 0.7 * diameter / 2.7)
    torque = float(thrust * diameter / 2 * rng.uniform(0.3, 0.8))
    if rng.random() < 0.8:
        stop = cortex + cone + float(rng.uniform(0.5, 3.0))
    else:
        stop = float(rng.uniform(max(0.55 * cortex, cone + 1.2), max(0.9 * cortex, cone + 1.3)))
    approach = float(rng.uniform(0.8, 4.0))
    return Pass(feed_mm_s=round(feed, 4), spindle_rpm=rpm, diameter_mm=diameter, point_angle_deg=angle,
                cortex_mm=round(cortex, 3), thrust_N=thrust, torque_Nmm=torque,
                cancellous_ratio=float(rng.uniform(0.08, 0.3)), chisel_share=float(rng.uniform(0.05, 0.2)),
                web_fraction=float(rng.uniform(0.1, 0.2)), kienzle_exponent=float(rng.uniform(0.15, 0.4)),
                lag_revolutions=float(rng.uniform(0.2, 0.7)), approach_s=approach, stop_depth_mm=float(stop),
                dwell_s=float(rng.uniform(0.2, 1.2)), retract_mm_s=float(rng.uniform(3, 10)))


def _duration(p: Pass, tail_s: float) -> float:
    stop_s = p.approach_s + p.stop_depth_mm / (p.feed_mm_s * p.feed_error)
    return stop_s + p.dwell_s + (p.stop_depth_mm + p.feed_mm_s * p.approach_s) / p.retract_mm_s + tail_s


def _column_z(trace, p: Pass) -> np.ndarray:
    return trace.column_mm(p.cortex_mm, p.cone_mm) / p.diameter_mm


def _clogging_loads(trace, p: Pass, clog) -> tuple[np.ndarray, np.ndarray]:
    """Thrust and torque excess of a drawn clogging law along the trace."""
    z = _column_z(trace, p)
    excess = p.thrust_N * clog.growth(z)
    d = trace.depth_mm
    if trace.breakthrough_s is not None:
        after = trace.time_s >= trace.breakthrough_s
        share = np.clip((p.cortex_mm + p.cone_mm - np.maximum.accumulate(d)) / p.cone_mm, 0.0, 1.0)
        if clog.after == "cone":
            factor = share
        elif clog.after == "retained":
            factor = share + clog.retained * (1 - share)
        else:
            factor = np.exp(-np.clip(trace.time_s - trace.breakthrough_s, 0.0, None) / clog.decay_s)
        excess = np.where(after, excess * factor, excess)
    excess = excess * np.clip(trace.pushing, 0.0, 1.0)
    return excess, clog.torque_per_thrust_mm * excess


def _spindle_angle(trace) -> np.ndarray:
    rpm = trace.extras["rpm"]
    step = float(trace.time_s[1] - trace.time_s[0])
    return 2 * math.pi * np.concatenate([[0.0], np.cumsum(0.5 * (rpm[1:] + rpm[:-1]) / 60.0 * step)])


def _write(path: Path, header: dict | None, t, thrust, torque, torque_unit: str, time_fmt: str) -> None:
    lines = [f"# {k} = {json.dumps(v) if isinstance(v, str) else repr(float(v))}" for k, v in (header or {}).items()]
    columns = ["time_s", "thrust_N"] + ([f"torque_{torque_unit}"] if torque is not None else [])
    data = np.column_stack([t, thrust] + ([torque] if torque is not None else []))
    fmt = [time_fmt, "%.7g"] + (["%.7g"] if torque is not None else [])
    with open(path, "w") as f:
        f.write("\n".join(lines + [",".join(columns)]) + "\n")
        np.savetxt(f, data, fmt=fmt, delimiter=",")


def make_case(kind: str, seed: int, split: str, directory: Path) -> Case:
    """Draw one case of ``kind`` on ``split`` from ``seed`` and write its files into ``directory``."""
    rng = np.random.default_rng(seed)
    forms_of = TUNING if split == "tuning" else HELD_OUT
    decoy_kind = kind.split(":", 1)[1] if kind.startswith("decoy:") else None
    truth = set(NAMED.get(kind, set()))
    long = rng.random() < 0.25
    p = _pass(rng, long)
    tail = float(rng.uniform(0.5, 3.0))
    if decoy_kind in ("second_touch", "air_knock"):
        tail = float(rng.uniform(2.0, 3.5))
    if long:   # 18–22 s at 1 kHz: a logger started early and stopped late
        target = float(rng.uniform(18.0, 22.0))
        spare = target - _duration(replace(p, approach_s=0.0), 0.0)
        if spare > 1.0:
            share = float(rng.uniform(0.3, 0.7))
            p = replace(p, approach_s=spare * share)
            tail = spare * (1 - share)
    if decoy_kind in ("second_touch", "air_knock"):
        tail = max(tail, 2.0)
    forms: dict = {}
    params: dict = {}

    # the decoys that change the pass itself
    layers, rpm_of_load = (), None
    if decoy_kind in ("hard_layer", "soft_layer"):
        deepest = min(p.cortex_mm, p.stop_depth_mm - p.cone_mm)
        y0 = float(rng.uniform(p.cone_mm + 0.3, max(deepest - 1.2, p.cone_mm + 0.4)))
        y1 = min(y0 + float(rng.uniform(0.4, 1.5)), deepest - 0.1)
        w = float(rng.uniform(1.25, 1.6) if decoy_kind == "hard_layer" else rng.uniform(0.4, 0.7))
        layers = ((y0, y1, w),)
        params["layer"] = (y0, y1, w)
    if decoy_kind == "second_cortex":
        gap, second = float(rng.uniform(1.5, 4.0)), float(rng.uniform(1.0, 3.0))
        y0 = p.cortex_mm + gap
        p = replace(p, stop_depth_mm=y0 + second * float(rng.uniform(0.5, 1.0)))
        layers = ((y0, y0 + second, 1.0),)
        params["second_cortex"] = (y0, y0 + second)
    if decoy_kind == "feed_error":
        p = replace(p, feed_error=float(1 + rng.choice([-1, 1]) * rng.uniform(0.06, 0.15)))
    if decoy_kind == "spindle_slowdown":
        drop = float(rng.uniform(0.1, 0.25))
        kappa = drop / (1 - drop)
        rpm0, t_o = p.spindle_rpm, p.torque_Nmm
        rpm_of_load = lambda torque: rpm0 / (1 + kappa * np.clip(torque, 0, None) / t_o)
        params["speed_drop"] = drop
    rec_pass = replace(p, layers=layers)
    sim_pass = p if decoy_kind != "second_cortex" else p   # the simulation is unicortical
    if decoy_kind == "feed_error":
        sim_pass = replace(p, feed_error=1.0)

    pulsation = None
    duration = _duration(rec_pass, tail)
    step = 1.0 / max(8000.0, 4 * 2500.0)
    probe = cut(sim_pass, duration, step)
    cut_s = probe.feed_stop_s - probe.contact_s
    if "feed_pulsation" in truth:
        form = str(rng.choice(forms_of["feed_pulsation"]))
        low = max(2.0 / cut_s, 0.3)
        hz = float(math.exp(rng.uniform(math.log(low), math.log(max(3.0, low * 1.2)))))
        pulsation, pp = draw_pulsation(rng, form, float(rng.uniform(0.06, 0.35)), hz)
        forms["feed_pulsation"] = form
        params["pulsation"] = pp

    rec = cut(rec_pass, duration, step, modulation=pulsation, rpm_of_load=rpm_of_load)
    sim = cut(sim_pass, duration, step)
    t = rec.time_s
    F, T = rec.thrust_N.copy(), rec.torque_Nmm.copy()
    F_sim, T_sim = sim.thrust_N.copy(), sim.torque_Nmm.copy()

    # softening: a multiplicative loss of the cutting loads from contact on
    soft_on_clogging = False
    if "thermal_softening" in truth:
        form = str(rng.choice(forms_of["thermal_softening"]))
        in_contact = np.clip(t - rec.contact_s, 0.0, None)
        work = np.cumsum(np.clip(F, 0, None))
        work = work / max(float(np.interp(rec.feed_stop_s, t, work)), 1e-9)
        loss_fn, sp = draw_softening(rng, form, float(rng.uniform(0.08, 0.35)), rec.feed_stop_s - rec.contact_s)
        loss = np.where(t >= rec.contact_s, loss_fn(in_contact, work), 0.0)
        loss = np.clip(loss, 0.0, 0.9)
        F, T = F * (1 - loss), T * (1 - loss)
        soft_on_clogging = bool(rng.random() < 0.5)
        forms["thermal_softening"] = form
        params["softening"] = sp | {"on_clogging": soft_on_clogging}
    else:
        loss = np.zeros_like(t)

    # clogging in the recording (missing, too little in the simulation, or in both)
    z_bt = max(_column_z(sim, p).max(), 1e-3)
    background = (not truth & {"chip_clogging"} and kind not in ("complete_clogging",)
                  and rng.random() < 0.4 and z_bt > 0.3)
    if "chip_clogging" in truth or kind == "complete_clogging" or background:
        all_forms = tuple(forms_of["chip_clogging"])
        form = str(rng.choice(all_forms))
        rise = float(rng.uniform(0.15, 0.7) if ("chip_clogging" in truth or kind == "complete_clogging")
                     else rng.uniform(0.1, 0.4))
        clog = draw_clogging(rng, form, z_bt, rise, p.radius_mm)
        cF, cT = _clogging_loads(rec, p, clog)
        if soft_on_clogging:
            cF, cT = cF * (1 - loss), cT * (1 - loss)
        F, T = F + cF, T + cT
        params["clogging"] = {"form": form, "rise": rise, "torque_per_thrust_mm": clog.torque_per_thrust_mm,
                              "after": clog.after, **(clog.parameters or {})}
        if "chip_clogging" in truth and kind != "too_little_clogging":
            forms["chip_clogging"] = form
        if kind == "too_little_clogging":
            forms["chip_clogging"] = form
            weaker = replace(clog, growth=(lambda g, s: (lambda z: s * g(z)))(clog.growth, float(rng.uniform(0.25, 0.55))))
            sF, sT = _clogging_loads(sim, p, weaker)
            F_sim, T_sim = F_sim + sF, T_sim + sT
        elif "chip_clogging" not in truth:   # the simulation has it too
            sF, sT = _clogging_loads(sim, p, clog)
            F_sim, T_sim = F_sim + sF, T_sim + sT

    # decoys acting on the loads
    decoy = None
    span = (rec.full_engagement_s, rec.breakthrough_s or rec.feed_stop_s)
    extra_F = np.zeros_like(t)
    extra_T = np.zeros_like(t)
    if decoy_kind == "chip_break":
        t0 = float(rng.uniform(span[0] + 0.3 * (span[1] - span[0]), span[1] - max(0.15 * (span[1] - span[0]), 0.4)))
        drop = float(rng.uniform(0.1, 0.25))
        k = np.where(t >= t0, 1 - drop, 1.0)
        F, T = F * k, T * k
        decoy = {"start_s": t0, "end_s": rec.feed_stop_s, "channel": "both", "drop": drop}
    elif decoy_kind in ("hard_layer", "soft_layer"):
        y0, y1, _ = params["layer"]
        decoy = {"start_s": float(t[np.argmax(rec.depth_mm >= y0)]),
                 "end_s": float(t[np.argmax(rec.depth_mm >= min(y1 + p.cone_mm, rec.depth_mm.max() - 1e-6))]),
                 "channel": "both"}
    elif decoy_kind == "second_cortex":
        y0, _ = params["second_cortex"]
        decoy = {"start_s": float(t[np.argmax(rec.depth_mm >= y0)]), "end_s": rec.feed_stop_s, "channel": "both"}
    elif decoy_kind in ("feed_error", "spindle_slowdown"):
        decoy = {"start_s": rec.contact_s, "end_s": rec.feed_stop_s, "channel": "both"}
    elif decoy_kind == "thrust_wobble":
        hz, a = float(rng.uniform(0.5, 3.0)), float(rng.uniform(0.06, 0.15))
        F = F * (1 + a * np.sin(2 * math.pi * hz * t + rng.uniform(0, 6.28)))
        decoy = {"start_s": rec.contact_s, "end_s": rec.feed_stop_s, "channel": "thrust_N", "frequency_hz": hz}
    elif decoy_kind == "fixture_vibration":
        hz, a = float(rng.uniform(0.5, 3.0)), float(rng.uniform(0.06, 0.14))
        ratio, lag = float(rng.uniform(0.0, 0.4)), float(rng.uniform(math.pi / 3, 2 * math.pi / 3))
        ph = float(rng.uniform(0, 6.28))
        F = F * (1 + a * np.sin(2 * math.pi * hz * t + ph))
        T = T * (1 + a * ratio * np.sin(2 * math.pi * hz * t + ph - lag))
        decoy = {"start_s": rec.contact_s, "end_s": rec.feed_stop_s, "channel": "both", "frequency_hz": hz}
    elif decoy_kind == "torque_friction":
        t0 = float(rng.uniform(span[0], span[0] + 0.6 * (span[1] - span[0])))
        frac = float(rng.choice([-1, 1]) * rng.uniform(0.12, 0.3))
        T = T * (1 + frac * decoy_shapes.smooth_step(t, t0, float(rng.uniform(0.1, 1.0))))
        decoy = {"start_s": t0, "end_s": rec.feed_stop_s, "channel": "torque_Nmm", "fraction": frac}
    elif decoy_kind == "second_touch":
        t0 = rec.retraction_end_s + float(rng.uniform(0.2, tail - 1.2))
        width = float(rng.uniform(0.3, 0.8))
        bump = np.where((t > t0) & (t < t0 + width), np.sin(math.pi * (t - t0) / width) ** 2, 0.0)
        amp = float(rng.uniform(0.3, 0.8))
        F = F + amp * p.thrust_N * bump
        T = T + amp * p.torque_Nmm * bump
        decoy = {"start_s": t0, "end_s": t0 + width, "channel": "both"}
    elif decoy_kind == "air_knock":
        before = rng.random() < 0.5 and rec.contact_s > 1.0
        t0 = (float(rng.uniform(0.3, rec.contact_s - 0.5)) if before
              else rec.retraction_end_s + float(rng.uniform(0.1, tail - 1.0)))
        hz, decay = float(rng.uniform(5, 25)), float(rng.uniform(0.05, 0.15))
        amp = float(rng.uniform(0.2, 0.6))
        extra_F = decoy_shapes.ringing(t, t0, amp * p.thrust_N, hz, decay)
        extra_T = decoy_shapes.ringing(t, t0, amp * 0.5 * p.torque_Nmm, hz * 1.3, decay)
        decoy = {"start_s": t0, "end_s": t0 + 4 * decay, "channel": "both"}
    elif decoy_kind == "tare_jump":
        t0 = float(rng.uniform(0.2, max(rec.contact_s - 0.3, 0.3)))
        size = float(rng.choice([-1, 1]) * rng.uniform(0.04, 0.1))
        which = str(rng.choice(["thrust_N", "torque_Nmm", "both"]))
        if which in ("thrust_N", "both"):
            extra_F = size * p.thrust_N * (t >= t0)
        if which in ("torque_Nmm", "both"):
            extra_T = size * p.torque_Nmm * (t >= t0)
        decoy = {"start_s": t0, "end_s": t0 + 0.2, "channel": which, "size": size}

    # the sensor: drift (a mechanism), then the acquisition chain
    hw = draw_hardware(rng, p.thrust_N, p.torque_Nmm, long)
    if decoy_kind == "clock_error":
        hw = replace(hw, clock_scale=float(1 + rng.choice([-1, 1]) * rng.uniform(0.03, 0.08)),
                     stamps="ideal" if hw.stamps == "coarse" else hw.stamps)
        decoy = {"start_s": rec.contact_s * hw.clock_scale, "end_s": rec.feed_stop_s * hw.clock_scale,
                 "channel": "both", "clock_scale": hw.clock_scale}
    if decoy_kind == "saturation":
        hw = replace(hw, range_factor=(float(rng.uniform(0.8, 0.92)), hw.range_factor[1]))
    drift = None
    if "sensor_drift" in truth:
        form = str(rng.choice(forms_of["sensor_drift"]))
        which = str(rng.choice(["both", "both", "both", "thrust_N", "torque_Nmm"]))
        fns, dp = [None, None], {"channels": which}
        for c, (name, size) in enumerate((("thrust_N", p.thrust_N), ("torque_Nmm", p.torque_Nmm))):
            if which in (name, "both"):
                change = float(rng.choice([-1, 1]) * rng.uniform(0.04, 0.3) * size)
                fns[c], extra = draw_drift(rng, form, change, duration)
                dp[name] = {"change": change, **extra}
        drift = tuple(fns)
        forms["sensor_drift"] = form
        params["drift"] = dp
    acquired = acquire(hw, rng, t, F, T, _spindle_angle(rec), drift, extra_F, extra_T)
    if decoy_kind == "saturation":
        top = acquired["thrust_N_range"]
        clipped = np.flatnonzero(acquired["thrust_N"] >= top * 0.999)
        start = float(acquired["instants_s"][clipped[0]]) if clipped.size else rec.full_engagement_s
        end = float(acquired["instants_s"][clipped[-1]]) if clipped.size else rec.feed_stop_s
        decoy = {"start_s": start, "end_s": end, "channel": "thrust_N", "clipped_samples": int(clipped.size)}

    thrust, torque = acquired["thrust_N"], acquired["torque_Nmm"]
    has_torque = decoy_kind is not None or rng.random() >= 0.125
    unit = "Nm" if rng.random() < 0.35 else "Nmm"
    # channel faults: what the file says is not what it holds
    if decoy_kind == "polarity":
        which = str(rng.choice(["thrust_N", "torque_Nmm"]))
        if which == "thrust_N":
            thrust = -thrust
        else:
            torque = -torque
        decoy = {"channel": which}
    elif decoy_kind == "swapped":
        thrust, torque = torque / (1000.0 if unit == "Nm" else 1.0), thrust * (1000.0 if unit == "Nm" else 1.0)
        decoy = {"channel": "both"}
    elif decoy_kind == "cross_talk":
        share = float(rng.uniform(0.08, 0.2))
        c = share * p.torque_Nmm / p.thrust_N * float(rng.choice([-1, 1]))
        torque = torque + c * (thrust - hw.tare[0])
        decoy = {"channel": "torque_Nmm", "newton_mm_per_newton": c, "share": share}
    elif decoy_kind == "unit_scale":
        channel, factor, what = [(c, f, w) for c, f, w in decoy_shapes.UNIT_MISTAKES][int(rng.integers(4))]
        if channel == "thrust_N":
            thrust = thrust * factor
        else:
            torque = torque * factor
        decoy = {"channel": channel, "factor": factor, "what": what}
    if decoy_kind in ("polarity", "swapped", "cross_talk", "unit_scale"):
        decoy.update(start_s=0.0, end_s=float(duration))

    stamps = acquired["stamps_s"]
    first = float(stamps[0])
    name = f"{kind.replace(':', '-').replace('+', '-')}-{seed}"
    directory.mkdir(parents=True, exist_ok=True)
    header = {"feed_mm_s": p.feed_mm_s, "spindle_rpm": p.spindle_rpm, "drill_diameter_mm": p.diameter_mm,
              "point_angle_deg": p.point_angle_deg}
    rec_path = directory / f"{name}.csv"
    written_t = stamps + hw.epoch_s
    _write(rec_path, header, written_t, thrust, (torque / (1000.0 if unit == "Nm" else 1.0)) if has_torque else None,
           unit, time_fmt="%.6f" if hw.epoch_s else "%.7g")

    # the simulation: clean, 0–3 % off in cutting energy one time in four
    scale = float(1 + rng.uniform(-0.03, 0.03)) if rng.random() < 0.25 else 1.0
    sim_rate = float(rng.uniform(100, 1000))
    sim_clock = "contact" if rng.random() < 0.5 else "recording"
    if sim_clock == "contact":
        end = sim.feed_stop_s if rng.random() < 0.3 else sim.feed_stop_s + float(rng.uniform(0.3, 1.0))
        ts = np.arange(sim.contact_s, end, 1 / sim_rate)
        t_written = ts - sim.contact_s
    else:
        start = float(rng.uniform(0.1, max(sim.contact_s - 0.3, 0.2)))
        end = sim.feed_stop_s + 0.05 if rng.random() < 0.2 else float(rng.uniform(sim.retraction_end_s, duration))
        ts = np.arange(start, end, 1 / sim_rate)
        t_written = ts
    sim_unit = "Nm" if rng.random() < 0.3 else "Nmm"
    sim_path = directory / f"{name}-sim.csv"
    _write(sim_path, header if rng.random() < 0.8 else None, t_written, scale * np.interp(ts, sim.time_s, F_sim),
           (scale * np.interp(ts, sim.time_s, T_sim) / (1000.0 if sim_unit == "Nm" else 1.0)) if has_torque else None,
           sim_unit, time_fmt="%.7g")

    if decoy is not None:
        decoy = {"kind": decoy_kind, **{k: (v - first if k in ("start_s", "end_s") and decoy_kind not in
                                            ("polarity", "swapped", "cross_talk", "unit_scale") else v)
                                        for k, v in decoy.items()}}
    params.update(pass_={k: v for k, v in vars(p).items() if k != "layers"}, hardware=vars(hw),
                  simulation={"rate_hz": sim_rate, "clock": sim_clock, "scale": scale, "unit": sim_unit},
                  torque=has_torque, torque_unit=unit, duration_s=duration,
                  events={"contact_s": rec.contact_s - first, "full_engagement_s": rec.full_engagement_s - first,
                          "breakthrough_s": None if rec.breakthrough_s is None else rec.breakthrough_s - first,
                          "feed_stop_s": rec.feed_stop_s - first, "retraction_end_s": rec.retraction_end_s - first})
    case = Case(name, kind, split, seed, frozenset(truth), forms, decoy, rec_path, sim_path, long, params)
    (directory / f"{name}.truth.json").write_text(json.dumps(case.to_json(), indent=1, default=str))
    return case


def case_seeds(seed: int, split: str) -> list[tuple[str, int]]:
    """(class, case seed) of a standard run: seed·100000 + 1000·class index + i (+ 50000 held out)."""
    out = []
    offset = 50_000 if split == "held_out" else 0
    for k, kind in enumerate(classes(split)):
        for i in range(per_class(kind)):
            out.append((kind, seed * 100_000 + offset + k * 1000 + i))
    return out
