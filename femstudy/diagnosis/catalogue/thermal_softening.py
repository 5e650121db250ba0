"""Thermal softening: the cut heats the bone and the loads fall by a growing fraction.

Signature (any law of the heat's effect: an exponential or hyperbolic approach, a linear or a
diffusive √t growth, a loss tied to the work done, a delayed onset once the bone passes a
temperature): softening is the bone's, in the cut, so it

- **multiplies** the cutting loads (zero in air), by a **comparable fraction in both channels**
  (the same when the simulation's loads are all cutting; where they include a friction the heat
  does not soften, the channels' shares differ a little);
- is a **loss** that **grows with the time in contact** (from contact, never back).

Fit: H = 1 − s(t − t_c) on the thrust and 1 − κ s on the torque, s a non-negative combination of
the monotone I-splines of :mod:`..flexible` over the time in contact, on 2, 4 or 8 intervals
(variants, :data:`RESOLUTIONS`: the coarsest that fits pays for the fewest coefficients). When the
simulation has a chip friction of its own, which after breakthrough may fade with the cut or stay
while the drill feeds, one more variant reads it as staying, at the coarsest resolution
(:data:`FRICTION_STAYS`, read by the model's rise R).
Size: the thrust's loss s at the end of the cut.

Tests (:meth:`ThermalSoftening.checks`): ``part_of_the_loads`` — the loss at the end of the cut
is at most :data:`MAX_LOSS`; ``both_channels`` — with torque, κ lies within
:data:`KAPPA_RANGE`: a loss of one channel alone (friction on the drill's body, a sensor) is not
the bone softening.

Reading: the loss at the end of the cut and when half of it was reached; the fraction s and
time constant τ of the nearest s(1 − e^{−t/τ}) (the form of femstudy's generator).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize

from femstudy.diagnosis.catalogue.registry import (FRICTION_STAYS, Check, Layout, Parameter, Reading, Role, Term,
                                                  Variant, proportional_term, register)
from femstudy.diagnosis.flexible import monotone_basis

NAME = "thermal_softening"
#: Intervals of the monotone spline, one variant each, simplest first.
RESOLUTIONS = (2, 4, 8)
FLOOR = 0.05
#: The largest loss at the end of the cut that heat explains: it lowers the bone's strength by tens
#: of percent over the temperatures a cut reaches, never to nothing. A larger fitted loss is another
#: mechanism's excess cancelled (a clogging rising as the loads fall away), not the bone.
MAX_LOSS = 0.75
#: Torque's loss over the thrust's that a softening of the bone allows, and the parameter's bounds.
KAPPA_RANGE = (0.6, 1.6)
KAPPA_BOUNDS = (0.25, 4.0)


class ThermalSoftening:
    name = NAME
    role = Role.GAIN
    floor = FLOOR
    scans = False

    def available(self, problem) -> bool:
        return True

    def variants(self, problem, residual, base) -> list[Variant]:
        fades = [Variant((("intervals", n),), f"{n} intervals") for n in RESOLUTIONS]
        if not problem.has_chip_friction:
            return fades
        coarsest = RESOLUTIONS[0]
        return fades + [Variant((("intervals", coarsest), (FRICTION_STAYS, True)),
                                f"{coarsest} intervals, the simulated chip friction staying after breakthrough")]

    @staticmethod
    def intervals(variant: Variant) -> int:
        return variant.get("intervals", RESOLUTIONS[-1])

    def layout(self, problem, variant: Variant) -> Layout:
        k = self.intervals(variant) + 2
        names, lower, upper = [f"loss_{j}" for j in range(k)], [0.0] * k, [0.95] * k
        start, counted = [0.0] * k, [True] * k
        if problem.has_torque:
            names.append("kappa")
            lower.append(KAPPA_BOUNDS[0]), upper.append(KAPPA_BOUNDS[1]), start.append(1.0), counted.append(False)
        return Layout(tuple(names), np.array(lower), np.array(upper), np.array(start), np.array(counted))

    def basis(self, problem, t: np.ndarray, contact_t: float, intervals: int) -> np.ndarray:
        return monotone_basis(t - contact_t, 0.0, problem.cut_s, intervals)

    def term(self, problem, frame, variant, theta) -> Term:
        return proportional_term(problem, self.basis(problem, frame.t, frame.contact_t_s, self.intervals(variant)),
                                 theta)

    def loss(self, problem, fit, elapsed_s: np.ndarray) -> np.ndarray:
        n = self.intervals(fit.spec.variant(NAME))
        return self.basis(problem, np.asarray(elapsed_s), 0.0, n) @ fit.block(NAME)[:n + 2]

    def size(self, problem, fit) -> float:
        n = self.intervals(fit.spec.variant(NAME))
        return float(np.sum(fit.block(NAME)[:n + 2]))   # every I-spline is 1 at the end of the cut

    def checks(self, problem, fit, refit) -> list[Check]:
        loss = self.size(problem, fit)
        out = [Check("part_of_the_loads", loss <= MAX_LOSS, loss,
                     f"the loads lose {100 * loss:.0f} % by the end of the cut (heat takes at most "
                     f"{100 * MAX_LOSS:.0f} %: more is another mechanism's excess cancelled)")]
        if problem.has_torque:
            kappa = fit.value(f"{NAME}.kappa")
            out.append(Check("both_channels", KAPPA_RANGE[0] <= kappa <= KAPPA_RANGE[1], kappa,
                             f"the torque loses {kappa:.2f} times the thrust's fraction (a softening of the bone: "
                             f"{KAPPA_RANGE[0]:g}-{KAPPA_RANGE[1]:g})"))
        return out

    def reading(self, problem, fit, context) -> Reading:
        cut = problem.cut_s
        t = np.linspace(0.0, cut, 200)
        s = self.loss(problem, fit, t)
        total = float(s[-1])
        half = float(np.interp(0.5 * total, s, t)) if total > 0 else 0.0

        def misfit(x):
            fraction, log_tau = x
            return fraction * -np.expm1(-t / 10 ** log_tau) - s

        sol = optimize.least_squares(misfit, [min(max(total, 0.01), 0.9), math.log10(max(half, 0.05) * 1.44)],
                                     bounds=([0.0, -1.5], [0.95, 2.5]))
        fraction, tau = float(sol.x[0]), float(10 ** sol.x[1])
        params = (Parameter("loss_at_end_of_cut", round(total, 4)), Parameter("time_to_half_loss_s", round(half, 4)),
                  Parameter("fraction", round(fraction, 4)), Parameter("time_constant_s", round(tau, 4)),
                  Parameter("time_in_contact_s", round(cut, 4)))
        if problem.has_torque:
            params += (Parameter("torque_to_thrust_loss", round(fit.value(f"{NAME}.kappa"), 3)),)
        text = (f"From contact on, the loads fall below the simulation by a growing fraction: "
                f"{100 * total:.0f} % after {cut:.1f} s of cutting, half of it within {half:.2f} s "
                f"(close to {fraction:.3g}·(1 − exp(−t/{tau:.3g} s))). A loss that grows with time in contact and "
                f"scales both loads alike is the bone softening as the cut heats it.")
        return Reading(params, text)


register(ThermalSoftening())
