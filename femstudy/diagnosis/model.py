"""The forward model of the diagnosis: the simulation, the mechanisms of a subset and the nuisances.

On the band's model grid t (recording time), for channel c:

    y_c(t) = g_c · P_c(t) · [H_c(t) (S_c(τ') − R_c) + H_ψ,c(t) (R_c + ΔU_c(t))] + A_c(t) + tare_c

- τ'(t) = t − Δt + δ(t) is the simulation time the drill is at: the robust alignment's shift Δt
  (refined by a correction in every fit), plus the lead δ of a feed modulation (FEED mechanisms),
  frozen once τ' reaches the simulation's feed stop; after that τ' runs on in real time and the
  loads fall as simulated (what LOAD mechanisms add falls with them);
- S_c(τ'), the simulated load; R_c the part of it above its value at full engagement S_c,o, while
  it rises, and once it falls the same share of it, or the level it reached (:func:`friction_stays`)
  (what the simulation's own chip column adds, if it has one: :func:`_rise`); ΔU_c = Σ what LOAD
  mechanisms add;
- P_c = 1 + Σ m_c in contact, before the stop (FEED mechanisms), else 1;
- H_c = 1 − Σ s_c (GAIN mechanisms) on the cutting load, and H_ψ = 1 − (1 − ψ) Σ s_c on the
  friction of packed chips (the simulation's rise R and what LOAD mechanisms add): the heat softens
  the bone the lips cut, and may or may not soften that friction, so the share ψ ∈ [0, 1] it spares
  is fitted whenever a GAIN mechanism meets such a friction (:data:`GAIN_SPARES`; counted as a
  parameter only when it leaves 0; R is taken as 0 when the simulation rises by less than
  :data:`.problem.MATERIAL_RISE` of its engaged load);
- A_c = Σ d_c (SENSOR mechanisms); tare_c, the sensor's zero; g_c = 1 unless the calibration scale
  is admitted (:mod:`.diagnose`).

The parameters are laid out as: a shift correction [s] and a stop-depth correction [mm] (a
load-model simulation only), the tares, the scales (when admitted), each mechanism's parameters
(:mod:`.catalogue`), and the amplitudes of extra columns (a shape competing with the mechanisms,
:mod:`.verdict`). :func:`evaluate` returns the model and its derivatives with respect to all of
them, both smoothed to the band's instants.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from femstudy.diagnosis.baseline import ModelSimulation
from femstudy.diagnosis.catalogue import FRICTION_STAYS, MECHANISMS, Layout, Role, Term, Variant
from femstudy.diagnosis.problem import Problem

#: The share of a GAIN mechanism's loss spared on the friction of packed chips (the parameter ψ).
GAIN_SPARES = "gain_spares_friction"
#: Bounds of the shift correction [s] and of the stop-depth correction [mm].
SHIFT_RANGE_S = 0.25
STOP_RANGE_MM = 0.6


@dataclass(frozen=True)
class Frame:
    """The clock of one evaluation on the model grid: simulation time, depth, contact and stop."""

    t: np.ndarray               #: recording time [s]
    tau: np.ndarray             #: simulation time τ' [s]
    shift_s: float
    stop_tau_s: float           #: the simulation's stop on its own clock [s]
    stop_t_s: float             #: the stop on the recording's clock (after the lead) [s]
    contact_tau_s: float
    feed_mm_s: float
    revolution_s: float
    cutting: np.ndarray         #: in contact and before the stop

    @property
    def contact_t_s(self) -> float:
        return self.contact_tau_s + self.shift_s

    @property
    def depth_mm(self) -> np.ndarray:
        """Tip depth at the nominal feed (frozen at the stop) [mm]."""
        return self.feed_mm_s * np.clip(np.minimum(self.tau, self.stop_tau_s) - self.contact_tau_s, 0.0, None)

    fall: np.ndarray | None = None  #: 1 while cutting, then the simulated thrust over its value at the stop


@dataclass(frozen=True)
class Spec:
    """A model: the mechanisms of a subset with their variants, and extra (smoothed) columns."""

    variants: tuple[tuple[str, Variant], ...] = ()
    extra: tuple | None = None      #: per channel, smoothed columns (instants × k) of a competing shape

    @property
    def subset(self) -> frozenset:
        return frozenset(name for name, _ in self.variants)

    def variant(self, name: str) -> Variant:
        return dict(self.variants)[name]

    def with_extra(self, extra: tuple | None) -> "Spec":
        return Spec(self.variants, extra)

    def without(self, name: str) -> "Spec":
        return Spec(tuple((n, v) for n, v in self.variants if n != name), self.extra)

    def label(self) -> str:
        return "+".join(sorted(self.subset)) or "none"


@dataclass(frozen=True)
class ParameterLayout:
    """The full parameter layout of a spec: names, bounds, start, which count when active, blocks."""

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    start: np.ndarray
    counted_when_active: np.ndarray
    blocks: dict[str, slice] = field(default_factory=dict)      # mechanism -> slice
    scanned: float = 0.0

    def index(self, name: str) -> int:
        return self.names.index(name)


def layout(problem: Problem, spec: Spec) -> ParameterLayout:
    """The parameter layout of ``spec`` (see the module docstring)."""
    names, lower, upper, start, counted = ["shift_correction_s"], [-SHIFT_RANGE_S], [SHIFT_RANGE_S], [0.0], [False]
    if isinstance(problem.simulation, ModelSimulation):
        names.append("stop_correction_mm")
        lower.append(-STOP_RANGE_MM)
        upper.append(STOP_RANGE_MM)
        start.append(0.0)
        counted.append(False)
    for c in problem.channels:
        names.append(f"{c}_tare")
        lower.append(-np.inf)
        upper.append(np.inf)
        start.append(0.0)
        counted.append(False)
    if problem.calibrate:
        for c in problem.channels:
            names.append(f"{c}_scale")
            lower.append(0.5)
            upper.append(2.0)
            start.append(1.0)
            counted.append(False)
    roles = {MECHANISMS[name].role for name, _ in spec.variants}
    if Role.GAIN in roles and (Role.LOAD in roles or problem.has_chip_friction):
        names.append(GAIN_SPARES)
        lower.append(0.0)
        upper.append(1.0)
        start.append(0.0)
        counted.append(True)
    blocks, scanned = {}, 0.0
    for name, variant in spec.variants:
        block: Layout = MECHANISMS[name].layout(problem, variant)
        begin = len(names)
        names += [f"{name}.{n}" for n in block.names]
        lower += list(block.lower)
        upper += list(block.upper)
        start += list(block.start)
        counted += list(block.counted_when_active)
        blocks[name] = slice(begin, len(names))
        scanned += block.scanned
    if spec.extra is not None:
        for c, columns in enumerate(spec.extra):
            for k in range(len(columns)):
                names.append(f"shape_{problem.channels[c]}_{k}")
                lower.append(-np.inf)
                upper.append(np.inf)
                start.append(0.0)
                counted.append(False)
    return ParameterLayout(tuple(names), np.array(lower, float), np.array(upper, float), np.array(start, float),
                   np.array(counted, bool), blocks, scanned)


def _frame(problem: Problem, shift: float, stop_tau: float, lead: np.ndarray) -> tuple[Frame, int | None]:
    """The frame for a shift, a stop and a lead; the model-grid index where the feed stops (or None)."""
    t = problem.band.t_model
    tau = t - shift + lead
    k_stop = None
    if math.isfinite(stop_tau) and tau[-1] > stop_tau:
        k_stop = int(np.searchsorted(tau, stop_tau))
    sim = problem.simulation
    stop_t = float(t[-1])
    if k_stop is not None:
        if k_stop == 0:
            stop_t = float(t[0])
        else:
            stop_t = float(np.interp(stop_tau, tau[k_stop - 1:k_stop + 1], t[k_stop - 1:k_stop + 1]))
        tau = np.where(t > stop_t, stop_tau + (t - stop_t), tau)
    cutting = (tau >= sim.contact_s) & (t <= stop_t)
    g = problem.geometry
    return Frame(t, tau, shift, stop_tau, stop_t, sim.contact_s, g.feed_mm_s, g.revolution_s, cutting), k_stop


def _fall(problem: Problem, frame: Frame, thrust: np.ndarray, stop_tau: float) -> np.ndarray:
    """1 until the feed stops, then the simulated thrust over its value at the stop: what LOAD
    mechanisms add falls with the cutting load, however the simulation lets it fall."""
    if not math.isfinite(stop_tau):
        return np.ones_like(frame.tau)
    at_stop = float(problem.simulation.loads(np.array([stop_tau - 1e-6]), stop_tau)[0][0])
    after = frame.tau > stop_tau
    if abs(at_stop) < 1e-12:
        return np.where(after, 0.0, 1.0)
    return np.where(after, np.clip(thrust / at_stop, 0.0, 1.0), 1.0)


def _rise(S: np.ndarray, engaged: np.ndarray, stays: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """R, the simulation's own chip friction: the load above its engaged value S_o while it rises,
    and dR/dS. Once the load falls (after breakthrough, at the stop) the friction either fades with
    the cut, R = q S with q the largest share 1 − S_o/S so far (femstudy's clogging model: the
    packed chips leave with the cone), or, with ``stays``, keeps the level it reached while the
    load is at least that, R = min(S, level) (the packed chips stay while the drill feeds)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(S > engaged[:, None], 1.0 - engaged[:, None] / S, 0.0)
    if stays:
        excess = S * share
        level = np.maximum.accumulate(excess, axis=1)
        R = np.minimum(S, level)
        follows = ((excess >= level) & (excess > 0)) | (S <= level)
        return R, follows.astype(float)
    held = np.maximum.accumulate(share, axis=1)
    rising = (share >= held) & (share > 0)
    return S * held, np.where(rising, 1.0, held)


def friction_stays(spec: Spec) -> bool:
    """Whether the simulation's chip friction is read as staying after breakthrough: a GAIN
    mechanism's variant says so (:data:`.catalogue.FRICTION_STAYS`) and no LOAD mechanism is fitted.
    Beside a LOAD mechanism (a clogging, whose excess may stay or leave after breakthrough) the two
    readings trade with it, so there the friction fades as simulated by femstudy's own model."""
    roles = [MECHANISMS[name].role for name, _ in spec.variants]
    return Role.LOAD not in roles and any(variant.get(FRICTION_STAYS, False) for name, variant in spec.variants
                                          if MECHANISMS[name].role is Role.GAIN)


def _loads(problem: Problem, tau: np.ndarray, stop_tau: float) -> np.ndarray:
    F, T = problem.simulation.loads(tau, stop_tau)
    return np.vstack([F] + ([T] if problem.has_torque else []))


@dataclass(frozen=True)
class Evaluation:
    """The model at some parameters: smoothed to the band's instants (channels × instants), its
    derivatives (channels × instants × parameters), the frame, and the modelled loads g·H·P·U on
    the model grid (no tare, drift or extra columns).

    The derivatives and the slopes are computed when first read (``derivatives``): a fit reads
    them only at the parameters it accepts, not at a trial step it rejects."""

    model: np.ndarray
    frame: Frame
    loads: np.ndarray
    grid: np.ndarray         #: the model on the model grid, without extra columns (for figures)
    derivatives: Callable[[], tuple[np.ndarray, np.ndarray]] = field(repr=False, compare=False)

    @functools.cached_property
    def _derived(self) -> tuple[np.ndarray, np.ndarray]:
        return self.derivatives()

    @property
    def jacobian(self) -> np.ndarray:
        """Derivatives of :attr:`model` in every parameter (channels × instants × parameters)."""
        return self._derived[0]

    @property
    def slopes(self) -> np.ndarray:
        """g·H·P·dU/dτ on the model grid (for scans of a feed modulation)."""
        return self._derived[1]


def evaluate(problem: Problem, spec: Spec, lay: ParameterLayout, theta: np.ndarray) -> Evaluation:
    """The model at ``theta``, and its derivatives when read (see :class:`Evaluation`)."""
    t = problem.band.t_model
    n_ch, n_t, p = len(problem.channels), t.size, theta.size
    shift = problem.shift_s + theta[0]
    sim = problem.simulation
    model_sim = isinstance(sim, ModelSimulation)
    stop_tau = problem.stop_s
    if model_sim:
        stop_tau = stop_tau + theta[1] / problem.geometry.feed_mm_s
    terms: dict[str, Term] = {}
    values = {name: theta[block] for name, block in lay.blocks.items()}
    roles = {name: MECHANISMS[name].role for name in lay.blocks}

    # FEED: the lead and the load modulation (on the recording's clock, before the frame exists)
    lead = np.zeros(n_t)
    m = np.zeros((n_ch, n_t))
    frame, k_stop = _frame(problem, shift, stop_tau, lead)   # provisional while a feed leads the drill
    feeds = [name for name in lay.blocks if roles[name] is Role.FEED]
    for name in feeds:
        term = MECHANISMS[name].term(problem, frame, spec.variant(name), values[name])
        terms[name] = term
        lead += term.lead
        m += term.value
    if feeds:
        frame, k_stop = _frame(problem, shift, stop_tau, lead)
    on = frame.cutting.astype(float)
    m = m * on

    # the simulated load on the drill's clock
    S = _loads(problem, frame.tau, stop_tau)
    frame = replace(frame, fall=_fall(problem, frame, S[0], stop_tau))
    rise = GAIN_SPARES in lay.names and problem.has_chip_friction
    R, dR_dS = np.zeros_like(S), np.zeros_like(S)
    if rise:
        R, dR_dS = _rise(S, problem.engaged_loads, friction_stays(spec))
    C = np.zeros_like(S)
    for name in lay.blocks:
        if roles[name] is Role.LOAD:
            term = MECHANISMS[name].term(problem, frame, spec.variant(name), values[name])
            terms[name] = term
            C += term.value
    P = 1.0 + m
    s_gain = np.zeros((n_ch, n_t))
    A = np.zeros((n_ch, n_t))
    for name in lay.blocks:
        if roles[name] is Role.GAIN:
            term = MECHANISMS[name].term(problem, frame, spec.variant(name), values[name])
            terms[name] = term
            s_gain += term.value
        elif roles[name] is Role.SENSOR:
            term = MECHANISMS[name].term(problem, frame, spec.variant(name), values[name])
            terms[name] = term
            A += term.value
    phi = 1.0 - theta[lay.index(GAIN_SPARES)] if GAIN_SPARES in lay.names else 1.0
    H, H_phi = 1.0 - s_gain, 1.0 - phi * s_gain
    g = np.ones(n_ch)
    if problem.calibrate:
        g = np.array([theta[lay.index(f"{c}_scale")] for c in problem.channels])
    gP = g[:, None] * P
    HU = H * (S - R) + H_phi * (R + C)    # the loads with their losses
    core = gP * HU
    tares = np.array([theta[lay.index(f"{c}_tare")] for c in problem.channels])
    model = core + A + tares[:, None]
    band = problem.band
    ms = band.smooth_model(model)
    first_extra = len(lay.names) - (sum(len(cols) for cols in spec.extra) if spec.extra is not None else 0)
    if spec.extra is not None:
        k = first_extra
        for c, columns in enumerate(spec.extra):
            for column in columns:
                ms[c] += theta[k] * column
                k += 1

    def derivatives() -> tuple[np.ndarray, np.ndarray]:
        """The smoothed Jacobian and the slopes g·H·P·dU/dτ."""
        J = np.zeros((n_ch, n_t, p))
        h = 0.25 * float(t[1] - t[0])
        dS = (_loads(problem, frame.tau + h, stop_tau) - _loads(problem, frame.tau - h, stop_tau)) / (2 * h)
        dR = dR_dS * dS
        dC = np.zeros_like(S)
        for name in lay.blocks:
            if roles[name] is Role.LOAD:
                dC += np.gradient(terms[name].value, frame.tau, axis=1) if np.ptp(frame.tau) > 0 else 0.0
        dHU = H * (dS - dR) + H_phi * (dR + dC)
        # each mechanism's block written once (the blocks are disjoint), each term's derivatives
        # multiplied by what multiplies the term in the model
        for name, block in lay.blocks.items():
            if roles[name] is Role.LOAD:
                J[:, :, block] = terms[name].jacobian * (gP * H_phi)[:, :, None]
            elif roles[name] is Role.SENSOR:
                J[:, :, block] = terms[name].jacobian
            elif roles[name] is Role.GAIN:
                J[:, :, block] = -((gP * (S - R + phi * (R + C)))[:, :, None] * terms[name].jacobian)
            elif roles[name] is Role.FEED:
                # through the modulation and through the lead (τ' moves with δ); the lead is frozen
                # and the modulation ends once the feed stops
                lead_jac = terms[name].lead_jacobian
                if k_stop is not None:
                    lead_jac = lead_jac.copy()
                    lead_jac[t > frame.stop_t_s] = lead_jac[max(k_stop - 1, 0)]
                m_jac = terms[name].jacobian * on[None, :, None]
                J[:, :, block] = (g[:, None] * HU)[:, :, None] * m_jac + (gP * dHU)[:, :, None] * lead_jac[None, :, :]
        if GAIN_SPARES in lay.names:
            J[:, :, lay.index(GAIN_SPARES)] = gP * s_gain * (R + C)
        J[:, :, 0] = -gP * dHU
        if model_sim:
            hs = 0.02
            up = _loads(problem, frame.tau, stop_tau + hs / problem.geometry.feed_mm_s)
            down = _loads(problem, frame.tau, stop_tau - hs / problem.geometry.feed_mm_s)
            J[:, :, 1] = gP * H * (up - down) / (2 * hs)
        for c, name in enumerate(problem.channels):
            J[c, :, lay.index(f"{name}_tare")] = 1.0
            if problem.calibrate:
                J[c, :, lay.index(f"{name}_scale")] = P[c] * HU[c]
        Js = np.stack([band.smooth_columns(J[c]) for c in range(n_ch)])
        if spec.extra is not None:
            k = first_extra
            for c, columns in enumerate(spec.extra):
                for column in columns:
                    Js[c, :, k] = column
                    k += 1
        return Js, gP * dHU

    return Evaluation(ms, frame, core, model, derivatives)
