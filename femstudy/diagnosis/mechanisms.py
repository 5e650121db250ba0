"""The candidate mechanisms and the simulation they modify (the forward model of the diagnosis).

With t the recording's time and τ(t) the simulation time (see :mod:`.baseline`), the modelled
thrust and torque are

    F(t) = [S_F(τ) + C(t)] · P(t) · H(t) + F_tare + r_F t
    T(t) = [S_T(τ) + k_T C(t)] · P(t) · H(t) + T_tare + r_T t

- alignment (always): τ = t − Δt; the tare offsets F_tare, T_tare (sensor zero); for a
  load-model simulation the depth at which the feed stopped. With ``calibrate``, also a scale
  g_F, g_T on each channel's simulated load, S_F → g_F S_F (with C), S_T → g_T S_T: the
  calibration of the cutting energy, the thesis's "initial cutting force" that the models are
  matched to before the rise is read (see :mod:`.diagnose` for when it is admitted). None of
  these is physics; they are reported, never diagnosed.
- ``chip_clogging`` (Eqs 3.16/3.19, as in :mod:`femstudy.drilling.history`, generalised):
  C = F_o (exp(p z) − 1) w(d), z = max(min(d, h) − l − L0, 0)/D the chip column past full
  engagement and an onset L0 ≥ 0, in diameters (frozen at breakthrough); w(d) the share s(d) of
  the tip cone still in cortex, and after breakthrough s + ρ(1 − s): a fraction ρ of the chips
  stays packed in the cortical hole. F_o is the simulated thrust at full engagement. The torque
  gains k_T C with k_T = R μ_w l_w / M ≥ 0. Fitted: p ≥ 0, L0, ρ ∈ [0, 1] (when the simulation
  breaks through) and, with torque, k_T. L0 = 0 and ρ = 0 is the thesis's form.
- ``feed_pulsation``: the feed f(t) = f (1 + m(t)), m = a sin ωt + b cos ωt, ω = 2π f_p ≥ 2π/T_cut
  (at least one period in the cut: slower is a feed-rate error)
  (amplitude A = √(a² + b²), phase atan2(b, a)), its pulse-shaped form of sharpness κ, or a
  sweep of its frequency by ±r of f_p over half the cut (:func:`feed_modulation`). The drill runs ahead of the nominal depth by f δ(t),
  δ = ∫_{contact}^{t} m dt, so the simulation is read at τ = t − Δt + δ(t), and the cutting
  load, proportional to the feed per revolution, is scaled by P = 1 + m in contact. After the
  feed stops (the instant τ reaches the simulation's stop) δ is frozen and P = 1.
- ``sensor_drift``: r_F t and r_T t over the whole recording, in and out of contact.
- ``thermal_softening``: H = 1 − s (1 − exp(−(t − t_c)/τ_s)) after contact t_c.

Every term is evaluated on the band's model grid and smoothed like the recording. The linear
parameters (tares, drift rates, k_T, scales) are solved for inside the fit (variable projection).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from femstudy.diagnosis.band import Band
from femstudy.drilling.drill import Drill

MECHANISMS = ("chip_clogging", "feed_pulsation", "sensor_drift", "thermal_softening")

#: Nonlinear parameters: name -> (lower, upper, mechanism or None for alignment).
NONLINEAR = {
    "shift_s": (-0.5, 0.5, None),
    "stop_depth_mm": (0.1, None, None),  # upper bound: see Problem.bounds
    "growth_exponent": (0.0, 5.0, "chip_clogging"),
    "clogging_onset_mm": (0.0, None, "chip_clogging"),   # upper bound: see Problem.bounds
    "clogging_retained": (0.0, 1.0, "chip_clogging"),    # only when the simulation breaks through
    "pulsation_a": (-0.7, 0.7, "feed_pulsation"),
    "pulsation_b": (-0.7, 0.7, "feed_pulsation"),
    "pulsation_frequency_hz": (0.15, 3.5, "feed_pulsation"),
    "pulsation_sharpness": (0.0, 5.0, "feed_pulsation"),  # the pulse-shaped variant only
    "pulsation_sweep": (-0.7, 0.7, "feed_pulsation"),  # the swept variant only
    "softening_fraction": (0.0, 0.95, "thermal_softening"),
    "softening_log10_tau_s": (-1.0, 1.8, "thermal_softening"),
}


#: Optional parameters of the feed pulsation, fitted only when the plain sine leaves misfit.
PULSATION_VARIANTS = ("pulsation_sharpness", "pulsation_sweep")


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


@dataclass(frozen=True)
class Geometry:
    """Cutting conditions the mechanisms need: feed [mm/s], speed [rpm], drill and cortex [mm]."""

    feed_mm_s: float
    spindle_rpm: float
    drill: Drill
    cortex_mm: float

    @property
    def diameter_mm(self) -> float:
        return self.drill.diameter_mm

    @property
    def cone_mm(self) -> float:
        return self.drill.cone_length_mm


@dataclass
class Problem:
    """A recording, smoothed at the band's instants, and the simulation to modify."""

    band: Band
    channels: tuple[str, ...]            # "thrust_N" and possibly "torque_Nmm"
    y: np.ndarray                        # smoothed recording, channels × instants
    sigma: np.ndarray                    # noise of each smoothed sample, channels × instants
    sigma_raw: np.ndarray                # white-noise level of each raw channel
    simulation: object                   # TraceSimulation or ModelSimulation
    geometry: Geometry
    initial_force_N: float
    clogging_possible: bool
    calibrate: bool = False              # fit a scale on each channel's simulated cutting load
    noise: tuple | None = None           # a noise.Whitener per channel (GLS); None: σ only
    extra: tuple | None = None           # per channel, smoothed columns of a competing shape
    ones: np.ndarray = field(init=False)
    ramp: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.ones = np.ones(self.band.t_dec.size)
        self.ramp = self.band.smooth_model(self.band.t_model)

    @property
    def has_torque(self) -> bool:
        return len(self.channels) == 2

    @property
    def n_eff_factor(self) -> float:
        """Independent samples per analysis instant: 1 once residuals are whitened by the fitted
        noise model, else the band's white-noise factor."""
        return 1.0 if self.noise is not None else self.band.n_eff_factor

    def whiten(self, c: int, x: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Channel ``c``'s residual (or design columns, instants on axis 0) in noise units:
        L⁻¹x with the fitted noise covariance C = LLᵀ, else x/σ; over ``rows`` (mask) only."""
        if self.noise is not None:
            return self.noise[c].whiten(x, rows)
        w = 1.0 / self.sigma[c]
        scaled = x * (w[:, None] if x.ndim == 2 else w)
        return scaled if rows is None else scaled[rows]

    @property
    def cut_s(self) -> float:
        """Duration of the simulated cut inside the compared window, contact to stop [s]."""
        sim, g = self.simulation, self.geometry
        stop = sim.stop_s if math.isfinite(sim.stop_s) else float(self.band.t_model[-1])
        return max(min(stop, float(self.band.t_model[-1])) - sim.contact_s, 1e-3)

    @property
    def lowest_pulsation_hz(self) -> float:
        """A feed pulsation completes at least one period in the cut; a slower change of the feed
        is a feed-rate error, not a pulsation [Hz]."""
        return min(max(NONLINEAR["pulsation_frequency_hz"][0], 1.0 / self.cut_s),
                   0.5 * NONLINEAR["pulsation_frequency_hz"][1])

    @property
    def sweep_centre_s(self) -> float:
        """Where a swept pulsation's frequency is f_p: the middle of the cut [s] (simulation clock
        plus the alignment's few tens of milliseconds, which do not matter here)."""
        return self.simulation.contact_s + self.cut_s / 2

    @property
    def breaks_through(self) -> bool:
        """Whether the simulated drill passes the cortex inside the compared window."""
        sim, g = self.simulation, self.geometry
        if sim.stop_is_parameter:
            deepest = sim.stop_depth_mm
        else:
            deepest = g.feed_mm_s * (min(sim.stop_s, float(self.band.t_model[-1])) - sim.contact_s)
        return deepest > g.cortex_mm + 0.5 * g.cone_mm

    def clogging_span(self, params: dict) -> float:
        """z at breakthrough: the chip column past full engagement and the onset, in diameters."""
        g = self.geometry
        return max(g.cortex_mm - g.cone_mm - params.get("clogging_onset_mm", 0.0), 0.0) / g.diameter_mm

    def nonlinear_names(self, subset: frozenset, variant: tuple = ()) -> list[str]:
        """Alignment parameters, then each mechanism's; the pulsation's optional sharpness and
        sweep only when named in ``variant``; clogging's retained fraction only when the
        simulation breaks through."""
        names = ["shift_s"] + (["stop_depth_mm"] if self.simulation.stop_is_parameter else [])
        return names + [n for n, (_, _, mech) in NONLINEAR.items()
                        if mech in subset and (n not in PULSATION_VARIANTS or n in variant)
                        and (n != "clogging_retained" or self.breaks_through)]

    def held_out_fixed_names(self, subset: frozenset) -> list[str]:
        """Nonlinear parameters a held-out refit keeps at the full fit's values: the alignment
        (pinned by a few instants, the ramp or the stop, that a block may hold) and clogging's
        retained fraction ρ (pinned only by the instants after breakthrough: without them it
        is free and its extrapolation meaningless)."""
        retained = ["clogging_retained"] if "clogging_retained" in self.nonlinear_names(subset) else []
        return self.nonlinear_names(frozenset()) + retained

    def linear_names(self, subset: frozenset) -> list[list[str]]:
        """Names of the linear parameters of each channel, in the order of :meth:`design`'s columns
        (the clogging torque gain, when present, last)."""
        out = []
        for i, c in enumerate(self.channels):
            names = ([f"{c}_scale"] if self.calibrate else []) + [f"{c}_tare"]
            if "sensor_drift" in subset:
                names.append(f"{c}_drift_per_s")
            if self.extra is not None:
                names += [f"{c}_shape_{k}" for k in range(len(self.extra[i]))]
            if c == "torque_Nmm" and "chip_clogging" in subset:
                names.append("torque_gain_Nmm_per_N")
            out.append(names)
        return out

    def bounds(self, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds; a load model's stop lies between 0.1 mm and the deepest the
        drill can have gone in the recording."""
        room = max(0.8 * (self.geometry.cortex_mm - self.geometry.cone_mm), 0.05)
        limits = {**NONLINEAR, "stop_depth_mm": (0.1, getattr(self.simulation, "max_depth_mm", None) or 100.0, None),
                  "clogging_onset_mm": (0.0, room, "chip_clogging"),
                  "pulsation_frequency_hz": (self.lowest_pulsation_hz, NONLINEAR["pulsation_frequency_hz"][1], None)}
        lo = np.array([limits[n][0] for n in names])
        hi = np.array([limits[n][1] for n in names])
        return lo, hi

    def terms(self, params: dict, t: np.ndarray | None = None) -> dict:
        """The forward model's pieces at times ``t`` (default the model grid), unsmoothed:
        ``thrust`` and ``torque`` (mechanisms applied, no linear terms) and ``clog`` (C·P·H,
        the column k_T multiplies)."""
        t = self.band.t_model if t is None else t
        sim, g = self.simulation, self.geometry
        shift = params.get("shift_s", 0.0)
        tau_c = sim.contact_s
        t_contact = tau_c + shift
        if sim.stop_is_parameter:
            stop = tau_c + params["stop_depth_mm"] / g.feed_mm_s
        else:
            stop = sim.stop_s
        tau = t - shift
        scale = np.ones_like(t)
        if "pulsation_frequency_hz" in params:
            m, lead = feed_modulation(params, t, t_contact, self.sweep_centre_s, self.cut_s / 2)
            tau = tau + lead
            scale = 1.0 + m
        if math.isfinite(stop) and tau[-1] > stop:
            k = int(np.searchsorted(tau, stop))
            t_stop = t[0] if k == 0 else float(np.interp(stop, tau[k - 1:k + 1], t[k - 1:k + 1]))
            after = t > t_stop
            tau = np.where(after, stop + (t - t_stop), tau)
            scale = np.where(after, 1.0, scale)
        F, T = sim.loads(tau, stop)
        clog = None
        if "growth_exponent" in params:
            d = g.feed_mm_s * np.clip(np.minimum(tau, stop) - tau_c, 0.0, None)
            inside = np.minimum(d, g.cortex_mm)
            z = np.maximum(inside - g.cone_mm - params.get("clogging_onset_mm", 0.0), 0.0) / g.diameter_mm
            share = np.clip(inside - np.maximum(d - g.cone_mm, 0.0), 0.0, g.cone_mm) / g.cone_mm
            if "clogging_retained" in params:  # chips still packed in the cortical hole after breakthrough
                share = np.where(d > g.cortex_mm, share + params["clogging_retained"] * (1.0 - share), share)
            fall = np.clip(1.0 - (tau - stop) * g.spindle_rpm / 60.0, 0.0, 1.0) if math.isfinite(stop) else 1.0
            clog = self.initial_force_N * np.expm1(params["growth_exponent"] * z) * share * fall
            F = F + clog
        if "softening_fraction" in params:
            tau_s = 10.0 ** params["softening_log10_tau_s"]
            scale = scale * (1.0 - params["softening_fraction"] * -np.expm1(-np.maximum(t - t_contact, 0.0) / tau_s))
        out = {"thrust_N": F * scale}
        if self.has_torque:
            out["torque_Nmm"] = T * scale
            if clog is not None:
                out["clog"] = clog * scale
        return out

    def design(self, subset: frozenset, params: dict):
        """Per channel, the smoothed part with fixed coefficient and the linear columns: scale
        (with ``calibrate``), tare, drift ramp, a competing shape's (``extra``), clogging
        torque (C·P·H)."""
        terms = self.terms(params)
        stack = [terms[c] for c in self.channels] + ([terms["clog"]] if "clog" in terms else [])
        smooth = self.band.smooth_model(np.vstack(stack))
        parts = []
        for i, c in enumerate(self.channels):
            cols = ([smooth[i]] if self.calibrate else []) + [self.ones]
            if "sensor_drift" in subset:
                cols.append(self.ramp)
            if self.extra is not None:
                cols.extend(self.extra[i])
            if c == "torque_Nmm" and "chip_clogging" in subset:
                cols.append(smooth[-1])
            parts.append((0.0 * self.ones if self.calibrate else smooth[i], np.column_stack(cols)))
        return parts

    def predict(self, params: dict, t: np.ndarray | None = None) -> dict:
        """The unsmoothed model of each channel at times ``t`` (default the model grid), with
        the linear parameters of ``params`` (``torque_gain_Nmm_per_N`` per newton of recorded
        extra thrust, i.e. on the scaled clogging term)."""
        t = self.band.t_model if t is None else t
        terms = self.terms(params, t)
        out = {}
        for c in self.channels:
            y = params.get(f"{c}_scale", 1.0) * terms[c] + params[f"{c}_tare"] + params.get(f"{c}_drift_per_s", 0.0) * t
            if c == "torque_Nmm" and "clog" in terms:
                y = y + params["torque_gain_Nmm_per_N"] * params.get("thrust_N_scale", 1.0) * terms["clog"]
            out[c] = y
        return out
