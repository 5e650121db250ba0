"""Synthetic force/torque recordings from femstudy's load models, with the rig's imperfections.

The drill approaches at the feed f, touches the bone at ``approach_s`` and cuts the cortex
and ``overtravel_mm`` of cancellous bone (or stops at ``stop_depth_mm``); then the feed stops,
the loads fall to zero within one spindle revolution and the drill retracts. The loads are
:func:`femstudy.drilling.history.evaluate` ("clogging" or "allotta") at the tip depth d(t).

Effects, each switchable (None) and recorded in the header:

- feed pulsation (the CNC's pulse-type feeding): f(t) = f·(1 + A·w(2π f_p t + φ)) with w a
  zero-mean sine or smoothed square ("pulse"); depth d(t) = ∫ f dt; the loads are evaluated
  at d(t) and scaled by f(t)/f, since cutting load is proportional to the feed per revolution;
- thermal softening: loads in contact × (1 − s·(1 − exp(−(t − t_contact)/τ)));
- spindle ripple: loads × (1 + r·sin(2π N t/60 + φ_r));
- sensor drift: offset + rate·t on both channels, over the whole recording;
- Gaussian noise on both channels, over the whole recording.

Ground truth (friction, initial loads, phase times) goes into the header as ``true_*`` keys.
Deterministic for a given ``seed``; a 20 s recording at 1 kHz takes a few milliseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from femstudy.drilling import Drill, registry
from femstudy.drilling.friction import BoneSet, load_bone_set
from femstudy.drilling.history import DrillingConditions, evaluate
from femstudy.errors import require
from femstudy.recordings.reader import Recording

#: (option, Effects field, parameter, default, help) of every switchable effect; 0 switches it off.
EFFECT_OPTIONS = [
    ("noise-thrust-N", "noise", "thrust_N", 0.3, "Gaussian thrust noise, standard deviation [N]"),
    ("noise-torque-Nmm", "noise", "torque_Nmm", 1.0, "Gaussian torque noise, standard deviation [N.mm]"),
    ("ripple", "ripple", "fraction", 0.05, "spindle-frequency ripple, fraction of the load"),
    ("pulsation", "pulsation", "amplitude", 0.2, "feed pulsation amplitude, fraction of the feed"),
    ("pulsation-hz", "pulsation", "frequency_hz", 1.0, "feed pulsation frequency [Hz]"),
    ("drift-N-per-s", "drift", "thrust_N_per_s", 0.05, "thrust sensor drift [N/s]"),
    ("drift-Nmm-per-s", "drift", "torque_Nmm_per_s", 0.2, "torque sensor drift [N.mm/s]"),
    ("softening", "softening", "fraction", 0.0, "thermal softening: final fractional load loss"),
    ("softening-s", "softening", "time_constant_s", 2.0, "thermal softening time constant [s]"),
]
#: the parameters that switch each effect on (any non-zero) or off (all 0)
SWITCHES = {"noise": ("thrust_N", "torque_Nmm"), "ripple": ("fraction",), "pulsation": ("amplitude",),
            "drift": ("thrust_N_per_s", "torque_Nmm_per_s"), "softening": ("fraction",)}


@dataclass(frozen=True)
class Noise:
    """White Gaussian noise: standard deviations of thrust [N] and torque [N·mm]."""

    thrust_N: float = 0.3
    torque_Nmm: float = 1.0


@dataclass(frozen=True)
class SpindleRipple:
    """Loads × (1 + fraction·sin(2π N t/60 + φ)), φ drawn from the seed."""

    fraction: float = 0.05


@dataclass(frozen=True)
class FeedPulsation:
    """Feed f(t) = f·(1 + amplitude·w(2π frequency_hz t + phase_rad)), w = sine or pulse."""

    amplitude: float = 0.2
    frequency_hz: float = 1.0
    phase_rad: float = 0.0
    shape: str = "sine"


@dataclass(frozen=True)
class SensorDrift:
    """Sensor offset(t) = offset + rate·t [N, N·mm], t from the start of the recording."""

    thrust_N_per_s: float = 0.05
    torque_Nmm_per_s: float = 0.2
    thrust_offset_N: float = 0.0
    torque_offset_Nmm: float = 0.0


@dataclass(frozen=True)
class ThermalSoftening:
    """Loads in contact × (1 − fraction·(1 − exp(−t_contact/time_constant_s)))."""

    fraction: float = 0.25
    time_constant_s: float = 2.0


@dataclass(frozen=True)
class Effects:
    """Which imperfections to add; None switches one off. The default is a realistic rig."""

    noise: Noise | None = Noise()
    ripple: SpindleRipple | None = SpindleRipple()
    pulsation: FeedPulsation | None = FeedPulsation()
    drift: SensorDrift | None = SensorDrift()
    softening: ThermalSoftening | None = None

    @classmethod
    def none(cls) -> "Effects":
        """The load model alone."""
        return cls(noise=None, ripple=None, pulsation=None, drift=None, softening=None)

    @classmethod
    def from_options(cls, values: dict[str, float | None], clean: bool = False,
                     pulsation_shape: str = "sine") -> "Effects":
        """Effects from :data:`EFFECT_OPTIONS` values keyed by option name (``"noise-thrust-N"``).

        A value of None takes the option's default (0 when ``clean``); an effect whose switch
        parameters are all 0 is off. Drift rates may be negative, every other value is >= 0.
        """
        chosen: dict[str, dict] = {group: {} for group in SWITCHES}
        for option, group, field, default, _ in EFFECT_OPTIONS:
            given = values.get(option)
            require(given is None or given >= 0 or group == "drift", f"--{option} must be >= 0, got {given}")
            chosen[group][field] = given if given is not None else (0.0 if clean else default)
        chosen["pulsation"]["shape"] = pulsation_shape
        kinds = {"noise": Noise, "ripple": SpindleRipple, "pulsation": FeedPulsation, "drift": SensorDrift,
                 "softening": ThermalSoftening}
        return cls(**{group: kinds[group](**chosen[group]) if any(chosen[group][f] != 0 for f in switch) else None
                      for group, switch in SWITCHES.items()})

    def names(self) -> list[str]:
        return [label for label, on in (("noise", self.noise), ("spindle_ripple", self.ripple),
                                        ("feed_pulsation", self.pulsation), ("sensor_drift", self.drift),
                                        ("thermal_softening", self.softening)) if on is not None]


def _modulation(pulsation: FeedPulsation | None, t: np.ndarray) -> np.ndarray:
    """Zero-mean feed modulation m(t), f(t) = f (1 + m)."""
    if pulsation is None:
        return np.zeros_like(t)
    angle = 2 * np.pi * pulsation.frequency_hz * t + pulsation.phase_rad
    if pulsation.shape == "sine":
        wave = np.sin(angle)
    else:  # a smoothed square wave: fast and slow halves, like a binding slide
        wave = np.tanh(3 * np.sin(angle)) / math.tanh(3)
    return pulsation.amplitude * wave


def _check_effects(e: Effects) -> None:
    if e.noise:
        require(e.noise.thrust_N >= 0 and e.noise.torque_Nmm >= 0, "noise levels must be >= 0")
    if e.ripple:
        require(0 <= e.ripple.fraction < 1, f"spindle ripple must lie in [0, 1), got {e.ripple.fraction}")
    if e.pulsation:
        p = e.pulsation
        require(0 <= p.amplitude < 1, f"feed pulsation amplitude must lie in [0, 1), got {p.amplitude}")
        require(p.frequency_hz > 0, f"feed pulsation frequency must be positive, got {p.frequency_hz}")
        require(p.shape in ("sine", "pulse"), f"feed pulsation shape must be sine or pulse, got '{p.shape}'")
    if e.softening:
        require(0 <= e.softening.fraction < 1, f"softening fraction must lie in [0, 1), got {e.softening.fraction}")
        require(e.softening.time_constant_s > 0, "softening time constant must be positive")


def synthesize(feed_mm_s: float = 1.5, spindle_rpm: float = 1500.0, *, cortex_mm: float = 6.0,
               bone: str | BoneSet = "bovine", mu_f: float | None = None, mu_w: float | None = None,
               u1_MPa: float | None = None, u2_MPa: float | None = None, model: str = "clogging",
               drill_diameter_mm: float = 2.7, point_angle_deg: float = 90.0,
               sample_rate_hz: float = 1000.0, approach_s: float = 2.0, overtravel_mm: float = 2.0,
               stop_depth_mm: float | None = None, tail_s: float = 2.0, effects: Effects = Effects(),
               seed: int = 0, specimen: str = "synthetic", depth_column: bool = False,
               metadata: dict | None = None) -> Recording:
    """One synthetic recording (see the module docstring).

    Parameters
    ----------
    feed_mm_s, spindle_rpm : float
        Feed f [mm/s] and spindle speed N [rpm].
    cortex_mm : float
        Cortical thickness drilled through [mm].
    bone : str or BoneSet
        Friction (Eqs 4.5-4.7 at f, N) and specific cutting energies, unless ``mu_f``, ``mu_w``,
        ``u1_MPa``, ``u2_MPa`` are given.
    model : {"clogging", "allotta"}
        Cutting with chip evacuation (Eqs 3.16/3.19), or Allotta's cutting alone (Eqs 2.18-2.19).
    drill_diameter_mm, point_angle_deg : float
    sample_rate_hz, approach_s, overtravel_mm, stop_depth_mm, tail_s : float
        Sampling [Hz] and the timeline: approach before contact [s], travel past breakthrough
        [mm], depth where the feed stops [mm] (less than the cortex: a retraction), tail [s].
    effects : Effects
        Rig imperfections (noise, ripple, pulsation, drift, softening).
    seed : int
    specimen : str
    depth_column : bool
        Also record the tip depth [mm].
    metadata : dict, optional
        Extra header values.

    Returns
    -------
    Recording
        In s, N, N·mm; the ground truth (true_mu_f, true_mu_w, ...) in ``metadata``.

    Examples
    --------
    >>> rec = synthesize(2.0, 1500, effects=Effects.none())
    >>> round(rec.metadata["true_mu_f"], 3) > 0
    True
    """
    registry.get(model, "synthesis")
    require(100 <= sample_rate_hz <= 10_000, f"sample rate must lie in 100 Hz-10 kHz, got {sample_rate_hz}")
    require(approach_s > 0 and tail_s > 0, "approach_s and tail_s must be positive")
    _check_effects(effects)
    bone_set = load_bone_set(bone) if isinstance(bone, str) else bone
    drill = Drill(diameter_mm=drill_diameter_mm, point_angle_deg=point_angle_deg)
    base = DrillingConditions(feed_mm_s, spindle_rpm, cortex_mm, bone_set, drill)
    mf, mw = base.friction
    mf, mw = (mu_f if mu_f is not None else mf), (mu_w if mu_w is not None else mw)
    u1 = bone_set.u1_MPa if u1_MPa is None else u1_MPa
    u2 = bone_set.u2_MPa if u2_MPa is None else u2_MPa
    cond = DrillingConditions(feed_mm_s, spindle_rpm, cortex_mm, replace(bone_set, u1_MPa=u1, u2_MPa=u2), drill,
                              friction_override=(mf, mw))
    stop_depth = cortex_mm + overtravel_mm if stop_depth_mm is None else stop_depth_mm
    require(stop_depth > 0, f"stop depth must be positive, got {stop_depth}")
    rng = np.random.default_rng(seed)

    # time, feed and depth; the feed stops at the stop depth
    p = effects.pulsation
    slowest = 1 - (p.amplitude if p else 0.0)
    t_end_max = approach_s + stop_depth / (feed_mm_s * slowest) + tail_s
    t = np.arange(int(math.ceil(t_end_max * sample_rate_hz)) + 1) / sample_rate_hz
    ratio = 1 + _modulation(p, t)
    position = np.concatenate([[0.0], np.cumsum(0.5 * (ratio[1:] + ratio[:-1]) * np.diff(t))]) * feed_mm_s
    depth = position - np.interp(approach_s, t, position)
    t_stop = float(np.interp(stop_depth, depth, t))
    t = t[t <= t_stop + tail_s]
    depth, ratio = np.minimum(depth[: t.size], stop_depth), ratio[: t.size]
    times = {"contact": approach_s, "full engagement": float(np.interp(drill.cone_length_mm, depth, t)),
             "breakthrough": float(np.interp(cortex_mm, depth, t)) if stop_depth >= cortex_mm else None,
             "retraction": t_stop}

    # loads of the model at d(t), scaled by the instantaneous feed, stopped at retraction
    history = evaluate(model, cond, np.maximum(depth, 0.0) / feed_mm_s)
    scale = np.where((depth > 0) & (t < t_stop), ratio, 1.0)
    scale *= np.clip(1 - (t - t_stop) * spindle_rpm / 60.0, 0.0, 1.0)
    if effects.softening:
        s = effects.softening
        scale *= 1 - s.fraction * -np.expm1(-np.maximum(t - approach_s, 0.0) / s.time_constant_s)
    ripple_phase = float(rng.uniform(0, 2 * np.pi))
    if effects.ripple:
        scale *= 1 + effects.ripple.fraction * np.sin(2 * np.pi * spindle_rpm / 60 * t + ripple_phase)
    thrust = history.thrust_N * scale
    torque = history.torque_Nmm * scale
    if effects.drift:
        d = effects.drift
        thrust = thrust + d.thrust_offset_N + d.thrust_N_per_s * t
        torque = torque + d.torque_offset_Nmm + d.torque_Nmm_per_s * t
    if effects.noise:
        thrust = thrust + rng.normal(0.0, effects.noise.thrust_N, t.size)
        torque = torque + rng.normal(0.0, effects.noise.torque_Nmm, t.size)

    F0, T0 = cond.static_allotta()
    meta = {"feed_mm_s": float(feed_mm_s), "spindle_rpm": float(spindle_rpm),
            "drill_diameter_mm": float(drill_diameter_mm), "point_angle_deg": float(point_angle_deg),
            "specimen": specimen, "generator": "femstudy synth", "model": model, "seed": int(seed),
            "sample_rate_hz": float(sample_rate_hz), "cortex_mm": float(cortex_mm),
            "u1_MPa": float(u1), "u2_MPa": float(u2),
            "true_mu_f": float(mf), "true_mu_w": float(mw),
            "true_initial_force_N": float(F0), "true_initial_torque_Nmm": float(T0),
            "true_growth_exponent": float(cond.growth_exponent) if model == "clogging" else 0.0,
            "true_contact_s": times["contact"], "true_full_engagement_s": times["full engagement"]}
    if times["breakthrough"] is not None:
        meta["true_breakthrough_s"] = times["breakthrough"]
    meta["true_retraction_s"] = times["retraction"]
    meta["effects"] = effects.names()
    meta.update(_effect_parameters(effects, ripple_phase))
    meta.update(metadata or {})
    return Recording(time_s=t, thrust_N=thrust, torque_Nmm=torque,
                     depth_mm=depth if depth_column else None, metadata=meta,
                     source=f"<synthetic seed {seed}>")


def _effect_parameters(e: Effects, ripple_phase: float) -> dict:
    """Every effect's parameters, zero when it is off, so that a header always has all keys."""
    n, r, p, d, s = e.noise, e.ripple, e.pulsation, e.drift, e.softening
    return {"noise_thrust_N": n.thrust_N if n else 0.0, "noise_torque_Nmm": n.torque_Nmm if n else 0.0,
            "ripple_fraction": r.fraction if r else 0.0, "ripple_phase_rad": ripple_phase if r else 0.0,
            "pulsation_amplitude": p.amplitude if p else 0.0,
            "pulsation_frequency_hz": p.frequency_hz if p else 0.0,
            "pulsation_phase_rad": p.phase_rad if p else 0.0, "pulsation_shape": p.shape if p else "none",
            "drift_thrust_N_per_s": d.thrust_N_per_s if d else 0.0,
            "drift_torque_Nmm_per_s": d.torque_Nmm_per_s if d else 0.0,
            "drift_thrust_offset_N": d.thrust_offset_N if d else 0.0,
            "drift_torque_offset_Nmm": d.torque_offset_Nmm if d else 0.0,
            "softening_fraction": s.fraction if s else 0.0,
            "softening_time_constant_s": s.time_constant_s if s else 0.0}
