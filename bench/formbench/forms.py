"""Functional forms of the four catalogue mechanisms, several per mechanism, and the held-out split.

Each form is one plausible law for the mechanism, drawn with its own parameters from a seeded
generator. The effect sizes are set by what matters to a reader of the recording (the rise of
the thrust by breakthrough, the loss by the end of the cut, the change of the zero over the
record, the feed modulation's amplitude), so the forms are comparable.

=================  ==================================================================================
mechanism          forms (``name``: law)
=================  ==================================================================================
chip_clogging      relative thrust excess G over the chip column z (diameters), G(z_bt) = rise:
                   ``exponential`` (e^{pz} − 1, the thesis's), ``power`` (z^n, n 1.3–3),
                   ``onset_linear`` (linear after an onset of 20–50 % of the column),
                   ``logistic`` (an S-curve centred at 40–80 % of the column),
                   ``quadratic_mix`` (αu + (1 − α)u²), ``saturating`` (1 − e^{−z/λ}).
                   Torque excess k_T × thrust excess; after breakthrough the excess follows the cone
                   out of the cortex, or a fraction stays, or it decays in time; it is pushed only
                   while the drill feeds.
feed_pulsation     feed f(1 + m(t)): ``sine``, ``sawtooth`` (stick-slip, slow rise), ``pulse``
                   (tanh(κ sin)), ``chirp`` (frequency sweeping ×1.3–2.5), ``two_harmonic``
                   (a second harmonic of 30–70 %), ``wander`` (frequency modulated ±8–20 %),
                   ``intermittent`` (the slide stalls for part of each period and catches up).
sensor_drift       additive on the channels over the whole record: ``linear``, ``warmup``
                   (1 − e^{−(t + t_on)/τ}), ``quadratic``, ``sigmoid`` (a slow change over 2–6 s),
                   ``log_creep`` (ln(1 + t/τ)); one case in four drifts on one channel only.
thermal_softening  loads × (1 − loss(t)), t in contact: ``exponential`` (s(1 − e^{−t/τ})),
                   ``hyperbolic`` (s x/(1 + x)), ``linear``, ``sqrt`` (diffusive heating),
                   ``heat`` (1 − e^{−E/E₀}, E the cutting work so far), ``delayed`` (a smooth
                   step once the bone passes a temperature, 20–50 % into the cut).
=================  ==================================================================================

The held-out forms (:data:`HELD_OUT`) were drawn once, by :func:`split` with seed 2031 before
any diagnosis was run on this benchmark: half of each mechanism's forms (rounded down), and
half of the decoys. The diagnosis is tuned on the other forms only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

FORMS = {
    "chip_clogging": ("exponential", "power", "onset_linear", "logistic", "quadratic_mix", "saturating"),
    "feed_pulsation": ("sine", "sawtooth", "pulse", "chirp", "two_harmonic", "wander", "intermittent"),
    "sensor_drift": ("linear", "warmup", "quadratic", "sigmoid", "log_creep"),
    "thermal_softening": ("exponential", "hyperbolic", "linear", "sqrt", "heat", "delayed"),
}
DECOY_KINDS = ("chip_break", "hard_layer", "spindle_slowdown", "feed_error", "clock_error", "thrust_wobble",
               "torque_friction", "second_cortex", "fixture_vibration", "air_knock", "tare_jump", "second_touch",
               "polarity", "swapped", "cross_talk", "unit_scale", "saturation", "soft_layer")
SPLIT_SEED = 2031


def split(seed: int = SPLIT_SEED) -> tuple[dict, dict, tuple, tuple]:
    """(tuning forms, held-out forms, tuning decoys, held-out decoys): a seeded shuffle of each
    list, the first ⌊n/2⌋ held out."""
    rng = np.random.default_rng(seed)
    tuning, held = {}, {}
    for mechanism, names in FORMS.items():
        order = [names[i] for i in rng.permutation(len(names))]
        k = len(names) // 2
        held[mechanism] = tuple(sorted(order[:k]))
        tuning[mechanism] = tuple(sorted(order[k:]))
    order = [DECOY_KINDS[i] for i in rng.permutation(len(DECOY_KINDS))]
    k = len(DECOY_KINDS) // 2
    return tuning, held, tuple(sorted(order[k:])), tuple(sorted(order[:k]))


TUNING, HELD_OUT, TUNING_DECOYS, HELD_OUT_DECOYS = split()


@dataclass(frozen=True)
class Clogging:
    """A drawn clogging law: relative thrust excess G(z), torque per thrust excess [mm], and what
    happens after breakthrough."""

    form: str
    growth: Callable[[np.ndarray], np.ndarray]    #: G(z), z the column in diameters, G(z_bt) = rise
    rise: float
    torque_per_thrust_mm: float
    after: str                                     #: "cone", "retained" or "decay"
    retained: float = 0.0
    decay_s: float = 0.5
    parameters: dict | None = None


def draw_clogging(rng: np.random.Generator, form: str, z_bt: float, rise: float, radius_mm: float) -> Clogging:
    """Clogging of ``form`` whose thrust excess at breakthrough (column z_bt diameters) is ``rise`` × F_o."""
    u = lambda z: np.clip(np.asarray(z, float) / z_bt, 0.0, None)
    params: dict = {}
    if form == "exponential":
        p = float(rng.uniform(0.5, 2.5)) / z_bt * 2
        params["p_per_diameter"] = p
        growth = lambda z: rise * np.expm1(p * np.asarray(z, float)) / math.expm1(p * z_bt)
    elif form == "power":
        n = float(rng.uniform(1.3, 3.0))
        params["n"] = n
        growth = lambda z: rise * u(z) ** n
    elif form == "onset_linear":
        z0 = float(rng.uniform(0.2, 0.5))
        params["onset_fraction"] = z0
        growth = lambda z: rise * np.clip((u(z) - z0) / (1 - z0), 0.0, None)
    elif form == "logistic":
        c, w = float(rng.uniform(0.4, 0.8)), float(rng.uniform(0.08, 0.2))
        params.update(centre_fraction=c, width_fraction=w)
        s = lambda x: 1.0 / (1.0 + np.exp(-(x - c) / w))
        growth = lambda z: rise * (s(u(z)) - s(0.0)) / (s(1.0) - s(0.0))
    elif form == "quadratic_mix":
        a = float(rng.uniform(0.0, 0.5))
        params["linear_share"] = a
        growth = lambda z: rise * (a * u(z) + (1 - a) * u(z) ** 2)
    elif form == "saturating":
        lam = float(rng.uniform(0.3, 1.0))
        params["length_fraction"] = lam
        growth = lambda z: rise * -np.expm1(-u(z) / lam) / -math.expm1(-1.0 / lam)
    else:
        raise ValueError(form)
    after = str(rng.choice(["cone", "retained", "decay"]))
    return Clogging(form, growth, rise, float(rng.uniform(0.3, 1.4)) * radius_mm, after,
                    float(rng.uniform(0.2, 0.8)), float(rng.uniform(0.2, 1.0)), params)


def draw_pulsation(rng: np.random.Generator, form: str, amplitude: float, frequency_hz: float) -> tuple[Callable, dict]:
    """m(t) of ``form``: a zero-mean feed modulation of roughly ``amplitude`` at ``frequency_hz``."""
    phase = float(rng.uniform(0, 2 * math.pi))
    w = 2 * math.pi * frequency_hz
    params: dict = {"amplitude": amplitude, "frequency_hz": frequency_hz}
    if form == "sine":
        return (lambda t: amplitude * np.sin(w * t + phase)), params
    if form == "sawtooth":
        rise = float(rng.uniform(0.7, 0.95))
        params["rise_fraction"] = rise

        def m(t):
            x = np.mod(frequency_hz * t + phase / (2 * math.pi), 1.0)
            return amplitude * np.where(x < rise, -1 + 2 * x / rise, 1 - 2 * (x - rise) / (1 - rise))
        return m, params
    if form == "pulse":
        kappa = float(rng.uniform(1.5, 5.0))
        params["sharpness"] = kappa
        return (lambda t: amplitude * np.tanh(kappa * np.sin(w * t + phase)) / math.tanh(kappa)), params
    if form == "chirp":
        ratio = float(rng.uniform(1.3, 2.5)) ** float(rng.choice([-1, 1]))
        params["frequency_ratio"] = ratio

        def m(t):
            span = float(t[-1] - t[0]) or 1.0
            k = frequency_hz * (ratio - 1) / span
            return amplitude * np.sin(2 * math.pi * (frequency_hz * t + 0.5 * k * t * t) + phase)
        return m, params
    if form == "two_harmonic":
        b, psi = float(rng.uniform(0.3, 0.7)), float(rng.uniform(0, 2 * math.pi))
        params.update(second_harmonic=b)
        return (lambda t: amplitude * (np.sin(w * t + phase) + b * np.sin(2 * (w * t + phase) + psi)) / (1 + b / 2)), params
    if form == "wander":
        depth = float(rng.uniform(0.08, 0.2))
        fm = float(rng.uniform(0.05, 0.15))
        params.update(frequency_swing=depth, swing_hz=fm)
        beta = depth * frequency_hz / fm
        return (lambda t: amplitude * np.sin(w * t + beta * np.sin(2 * math.pi * fm * t) + phase)), params
    if form == "intermittent":
        stall = float(rng.uniform(0.2, 0.45))
        params["stall_fraction"] = stall
        low, high = -amplitude * 1.6, amplitude * 1.6 * stall / (1 - stall)

        def m(t):
            x = np.mod(frequency_hz * t + phase / (2 * math.pi), 1.0)
            edge = 0.06
            up = 0.5 * (1 + np.tanh((x - stall) / edge * 3)) * 0.5 * (1 + np.tanh((1 - x) / edge * 3))
            return low + (high - low) * up
        return m, params
    raise ValueError(form)


def draw_drift(rng: np.random.Generator, form: str, change: float, duration_s: float) -> tuple[Callable, dict]:
    """d(t) of ``form`` changing by ``change`` (signed, in the channel's unit) over the record."""
    params: dict = {}
    T = duration_s
    if form == "linear":
        shape = lambda t: t / T
    elif form == "warmup":
        tau, on = float(rng.uniform(3, 25)), float(rng.uniform(0, 8))
        params.update(tau_s=tau, on_s=on)
        base = lambda t: -np.expm1(-(t + on) / tau)
        shape = lambda t: (base(t) - base(0.0)) / (base(T) - base(0.0))
    elif form == "quadratic":
        a = float(rng.uniform(0.0, 0.4))
        params["linear_share"] = a
        shape = lambda t: a * t / T + (1 - a) * (t / T) ** 2
    elif form == "sigmoid":
        mid, width = float(rng.uniform(0.3, 0.7)) * T, float(rng.uniform(2.0, 6.0))
        params.update(mid_s=mid, width_s=width)
        s = lambda t: 1.0 / (1.0 + np.exp(-(t - mid) / width))
        shape = lambda t: (s(t) - s(0.0)) / (s(T) - s(0.0))
    elif form == "log_creep":
        tau = float(rng.uniform(0.5, 5.0))
        params["tau_s"] = tau
        shape = lambda t: np.log1p(t / tau) / math.log1p(T / tau)
    else:
        raise ValueError(form)
    return (lambda t: change * shape(np.asarray(t, float))), params


def draw_softening(rng: np.random.Generator, form: str, loss: float, cut_s: float) -> tuple[Callable, dict]:
    """loss(t_in_contact, work_fraction) of ``form`` reaching ``loss`` by the end of the cut
    (``cut_s`` in contact); ``work_fraction`` is the cutting work so far over the whole cut's."""
    params: dict = {"loss_at_end": loss}
    T = cut_s
    if form == "exponential":
        tau = float(rng.uniform(0.5, 6.0))
        params["tau_s"] = tau
        return (lambda t, e: loss * -np.expm1(-t / tau) / -math.expm1(-T / tau)), params
    if form == "hyperbolic":
        tau = float(rng.uniform(0.5, 6.0))
        params["tau_s"] = tau
        return (lambda t, e: loss * (t / tau / (1 + t / tau)) / (T / tau / (1 + T / tau))), params
    if form == "linear":
        return (lambda t, e: loss * t / T), params
    if form == "sqrt":
        return (lambda t, e: loss * np.sqrt(np.clip(t, 0, None) / T)), params
    if form == "heat":
        e0 = float(rng.uniform(0.3, 1.5))
        params["work_scale"] = e0
        return (lambda t, e: loss * -np.expm1(-e / e0) / -math.expm1(-1.0 / e0)), params
    if form == "delayed":
        start = float(rng.uniform(0.2, 0.5))
        params["start_fraction"] = start

        def f(t, e):
            x = np.clip((t / T - start) / (1 - start), 0.0, 1.0)
            return loss * x * x * (3 - 2 * x)
        return f, params
    raise ValueError(form)
