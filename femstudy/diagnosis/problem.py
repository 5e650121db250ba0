"""The diagnosis problem: the recording in the analysis band, the simulation, its alignment, the noise.

Built by :mod:`.prepare`; read by the forward model (:mod:`.model`), the fits and the tests.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from femstudy.diagnosis.band import Band
from femstudy.diagnosis.baseline import ModelSimulation, TraceSimulation
from femstudy.diagnosis.noise import Whitener
from femstudy.drilling.drill import Drill

#: A simulation whose thrust rises above its engaged value by less than this share has no chip
#: friction of its own (no rise R in the model, :mod:`.model`).
MATERIAL_RISE = 0.03


@dataclass(frozen=True)
class Geometry:
    """Cutting conditions: feed [mm/s], speed [rpm], drill and cortex [mm]."""

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

    @property
    def revolution_s(self) -> float:
        return 60.0 / self.spindle_rpm


@dataclass(frozen=True)
class Problem:
    """A recording smoothed at the band's instants and the simulation to compare it with.

    ``y`` and ``sigma`` are channels × instants; ``usable`` marks the instants the fits use (an
    event in air is left out), ``air`` those where the drill is surely off the bone (more than
    :data:`.prepare.AIR_MARGIN_S` from any simulated load). ``shift_s`` and ``stop_depth_mm`` are the
    robust alignment's (:func:`.prepare.align`); the fits refine them by a small correction.
    """

    band: Band
    channels: tuple[str, ...]
    y: np.ndarray
    sigma: np.ndarray
    sigma_raw: np.ndarray
    simulation: TraceSimulation | ModelSimulation
    geometry: Geometry
    initial_force_N: float
    clogging_possible: bool
    usable: np.ndarray
    air: np.ndarray
    shift_s: float = 0.0
    stop_depth_mm: float | None = None
    calibrate: bool = False
    noise: tuple[Whitener, ...] | None = None

    @property
    def has_torque(self) -> bool:
        return len(self.channels) == 2

    @property
    def n(self) -> int:
        """Instants used by the fits, over all channels."""
        return int(np.count_nonzero(self.usable)) * len(self.channels)

    @property
    def n_eff_factor(self) -> float:
        """Independent samples per instant: 1 once residuals are whitened by the noise model."""
        return 1.0 if self.noise is not None else self.band.n_eff_factor

    def whiten(self, c: int, x: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Channel ``c``'s residual (or columns, instants on axis 0) in noise units over ``rows``
        (mask, default all): L⁻¹x with the noise covariance C = LLᵀ, else x/σ."""
        if self.noise is not None:
            return self.noise[c].whiten(x, rows)
        w = 1.0 / self.sigma[c]
        scaled = x * (w[:, None] if x.ndim == 2 else w)
        return scaled if rows is None else scaled[rows]

    @property
    def stop_s(self) -> float:
        """The simulation's feed stop on its own clock [s] (infinite if it does not stop)."""
        sim = self.simulation
        if isinstance(sim, ModelSimulation):
            return sim.contact_s + (self.stop_depth_mm or sim.stop_depth_mm) / self.geometry.feed_mm_s
        return sim.stop_s

    @property
    def cut_s(self) -> float:
        """Duration of the simulated cut inside the compared window, contact to stop [s]."""
        end = float(self.band.t_model[-1]) - self.shift_s
        stop = self.stop_s if math.isfinite(self.stop_s) else end
        return max(min(stop, end) - self.simulation.contact_s, 1e-3)

    @property
    def contact_t(self) -> float:
        """Contact on the recording's clock [s]."""
        return self.simulation.contact_s + self.shift_s

    @property
    def deepest_mm(self) -> float:
        """The deepest the simulated drill goes inside the compared window [mm]."""
        return self.geometry.feed_mm_s * self.cut_s

    @property
    def breaks_through(self) -> bool:
        """Whether the simulated drill passes the cortex inside the compared window."""
        return self.deepest_mm > self.geometry.cortex_mm + 0.5 * self.geometry.cone_mm

    @property
    def clogging_span(self) -> float:
        """The chip column at the deepest point, past full engagement, in diameters."""
        g = self.geometry
        return max(min(g.cortex_mm, self.deepest_mm) - g.cone_mm, 0.0) / g.diameter_mm

    @functools.cached_property
    def engaged_loads(self) -> np.ndarray:
        """The simulated loads at full engagement (contact + cone/feed), per channel."""
        g = self.geometry
        loads = self.simulation.loads(np.array([self.simulation.contact_s + g.cone_mm / g.feed_mm_s]))
        return np.array([float(loads[0][0])] + ([float(loads[1][0])] if self.has_torque else []))

    @functools.cached_property
    def simulated_rise(self) -> float:
        """How far the simulated thrust rises above its engaged value, as a share of it."""
        F = self.simulation.loads(self.band.t_model - self.shift_s, self.stop_s)[0]
        return max(float(np.max(F)) / max(self.engaged_loads[0], 1e-12) - 1.0, 0.0)

    @property
    def has_chip_friction(self) -> bool:
        """Whether the simulation has a chip friction of its own: a thrust rising above its engaged
        value by at least :data:`MATERIAL_RISE` of it."""
        return self.simulated_rise > MATERIAL_RISE

    def peak(self, c: int) -> float:
        """The simulated load's peak on channel ``c`` [N or N·mm]."""
        loads = self.simulation.loads(self.band.t_model - self.shift_s, self.stop_s)
        load = loads[0] if self.channels[c] == "thrust_N" else loads[1]
        return max(float(np.max(np.abs(load))), 1e-12)
