"""The simulation the mechanisms modify: the forward model of the diagnosis.

With t the recording's time and τ(t) the simulation time (see :mod:`..baseline`), the modelled
thrust and torque are

    F(t) = [S_F(τ) + C(t)] · P(t) · H(t) + F_tare + Σ r_F c(t)
    T(t) = [S_T(τ) + k_T C(t)] · P(t) · H(t) + T_tare + Σ r_T c(t)

- alignment (always): τ = t − Δt; the tare offsets F_tare, T_tare (sensor zero); for a
  load-model simulation the depth at which the feed stopped. With ``calibrate``, also a scale
  g_F, g_T on each channel's simulated load, S_F → g_F S_F (with C), S_T → g_T S_T: the
  calibration of the cutting energy, the thesis's "initial cutting force" that the models are
  matched to before the rise is read (see :mod:`..diagnose` for when it is admitted). None of
  these is physics; they are reported, never diagnosed.
- each mechanism of the catalogue (:mod:`.registry`, one module each) acts through its hooks:
  a feed modulation m(t) with its depth lead (τ → τ + lead, P = 1 + m in contact; after the
  feed stops, the instant τ reaches the simulation's stop, the lead is frozen and P = 1), an
  extra thrust C with its torque k_T C, a factor H on the loads, or linear columns c(t) on the
  sensor reading (k_T and the r fitted linearly).

The catalogue: :mod:`.chip_clogging` (Eqs 3.16/3.19), :mod:`.feed_pulsation`,
:mod:`.sensor_drift`, :mod:`.thermal_softening`.

Every term is evaluated on the band's model grid and smoothed like the recording. The linear
parameters (tares, drift rates, k_T, scales) are solved for inside the fit (variable projection).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from femstudy.diagnosis.band import Band
from femstudy.diagnosis.mechanisms.registry import catalogue
from femstudy.drilling.drill import Drill

#: The alignment's nonlinear parameters: name -> (lower, upper); a load model's stop has its
#: upper bound from the simulation (:meth:`Problem.bounds`).
ALIGNMENT = {"shift_s": (-0.5, 0.5), "stop_depth_mm": (0.1, None)}


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
    def breaks_through(self) -> bool:
        """Whether the simulated drill passes the cortex inside the compared window."""
        sim, g = self.simulation, self.geometry
        if sim.stop_is_parameter:
            deepest = sim.stop_depth_mm
        else:
            deepest = g.feed_mm_s * (min(sim.stop_s, float(self.band.t_model[-1])) - sim.contact_s)
        return deepest > g.cortex_mm + 0.5 * g.cone_mm

    def nonlinear_names(self, subset: frozenset, variant: tuple = ()) -> list[str]:
        """Alignment parameters, then each mechanism's of ``subset`` in the catalogue's order; an
        optional parameter only when named in ``variant``, one with ``needs`` only when the
        problem meets it (clogging's retained fraction: when the simulation breaks through)."""
        names = ["shift_s"] + (["stop_depth_mm"] if self.simulation.stop_is_parameter else [])
        return names + [p.name for m in catalogue() if m.name in subset for p in m.parameters
                        if (not p.optional or p.name in variant) and (p.needs is None or p.needs(self))]

    def held_out_fixed_names(self, subset: frozenset) -> list[str]:
        """Nonlinear parameters a held-out refit keeps at the full fit's values: the alignment
        (pinned by a few instants, the ramp or the stop, that a block may hold) and those a
        mechanism marks ``held_out_fixed`` (clogging's retained fraction ρ, pinned only by the
        instants after breakthrough: without them it is free and its extrapolation meaningless)."""
        fixed = {p.name for m in catalogue() for p in m.parameters if p.held_out_fixed}
        return self.nonlinear_names(frozenset()) + [n for n in self.nonlinear_names(subset) if n in fixed]

    def linear_names(self, subset: frozenset) -> list[list[str]]:
        """Names of the linear parameters of each channel, in the order of :meth:`design`'s columns:
        scale, tare, the mechanisms' sensor columns, a competing shape's, the torque gains."""
        mechanisms = [m for m in catalogue() if m.name in subset]
        out = []
        for i, c in enumerate(self.channels):
            names = ([f"{c}_scale"] if self.calibrate else []) + [f"{c}_tare"]
            names += [term.name.format(channel=c) for m in mechanisms for term in m.linear]
            if self.extra is not None:
                names += [f"{c}_shape_{k}" for k in range(len(self.extra[i]))]
            if c == "torque_Nmm":
                names += [m.torque_gain for m in mechanisms if m.torque_gain]
            out.append(names)
        return out

    def bounds(self, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds; a load model's stop lies between 0.1 mm and the deepest the
        drill can have gone in the recording; a mechanism's bounds may depend on the problem."""
        limits = {**ALIGNMENT, "stop_depth_mm": (0.1, getattr(self.simulation, "max_depth_mm", None) or 100.0)}
        limits.update((p.name, p.bounds(self)) for m in catalogue() for p in m.parameters)
        lo = np.array([limits[n][0] for n in names])
        hi = np.array([limits[n][1] for n in names])
        return lo, hi

    def terms(self, params: dict, t: np.ndarray | None = None) -> dict:
        """The forward model's pieces at times ``t`` (default the model grid), unsmoothed:
        ``thrust_N`` and ``torque_Nmm`` (mechanisms applied, no linear terms) and, with torque,
        ``excess``: each acting mechanism's extra thrust C·P·H by name (the column its torque
        gain multiplies)."""
        t = self.band.t_model if t is None else t
        sim = self.simulation
        acting = [m for m in catalogue() if m.acts_in(params)]
        shift = params.get("shift_s", 0.0)
        tau_c = sim.contact_s
        t_contact = tau_c + shift
        if sim.stop_is_parameter:
            stop = tau_c + params["stop_depth_mm"] / self.geometry.feed_mm_s
        else:
            stop = sim.stop_s
        tau = t - shift
        scale = np.ones_like(t)
        for m in acting:
            if m.feed is not None:
                modulation, lead = m.feed(self, params, t, t_contact)
                tau = tau + lead
                scale = scale * (1.0 + modulation)
        if math.isfinite(stop) and tau[-1] > stop:
            k = int(np.searchsorted(tau, stop))
            t_stop = t[0] if k == 0 else float(np.interp(stop, tau[k - 1:k + 1], t[k - 1:k + 1]))
            after = t > t_stop
            tau = np.where(after, stop + (t - t_stop), tau)
            scale = np.where(after, 1.0, scale)
        F, T = sim.loads(tau, stop)
        excess = {}
        for m in acting:
            if m.excess is not None:
                excess[m.name] = m.excess(self, params, tau, stop)
                F = F + excess[m.name]
        for m in acting:
            if m.factor is not None:
                scale = scale * m.factor(self, params, t, t_contact)
        out = {"thrust_N": F * scale}
        if self.has_torque:
            out["torque_Nmm"] = T * scale
            out["excess"] = {name: C * scale for name, C in excess.items()}
        return out

    def torque_of_excess(self, params: dict, terms: dict) -> np.ndarray | float:
        """k_T·g_F·C summed over the mechanisms with an extra thrust: the torque they add, with
        each gain per newton of recorded extra thrust (the thrust's scale g_F applied)."""
        out = 0.0
        for m in catalogue():
            if m.name in terms.get("excess", {}) and m.torque_gain in params:
                out = out + params[m.torque_gain] * params.get("thrust_N_scale", 1.0) * terms["excess"][m.name]
        return out

    def design(self, subset: frozenset, params: dict):
        """Per channel, the smoothed part with fixed coefficient and the linear columns: scale
        (with ``calibrate``), tare, the mechanisms' sensor columns (a drift ramp), a competing
        shape's (``extra``), the torque gains' (C·P·H)."""
        terms = self.terms(params)
        mechanisms = [m for m in catalogue() if m.name in subset]
        gained = [m.name for m in mechanisms if m.torque_gain and m.name in terms.get("excess", {})]
        stack = [terms[c] for c in self.channels] + [terms["excess"][name] for name in gained]
        smooth = self.band.smooth_model(np.vstack(stack))
        parts = []
        for i, c in enumerate(self.channels):
            cols = ([smooth[i]] if self.calibrate else []) + [self.ones]
            cols += [term.column(self) for m in mechanisms for term in m.linear]
            if self.extra is not None:
                cols.extend(self.extra[i])
            if c == "torque_Nmm":
                cols += list(smooth[len(self.channels):])
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
            if c == "torque_Nmm" and terms["excess"]:
                y = y + self.torque_of_excess(params, terms)
            out[c] = y
        return out
