"""Sensor drift: the zero of a channel moves smoothly over the whole record, in air as in contact.

Signature (any law: linear, an amplifier's warm-up, a creep, a slow sigmoid): drift is the
instrument's, not the cut's, so it

- **adds** to a channel (it does not scale with the load) and each channel drifts on its own;
- is **present in air as well as in contact**: the load-free stretches before contact and after
  retraction show it. A trend that only the cut shows is not a drift.

Fit: on each channel a Legendre series P₁ … P_d over the compared window (d = 1, 2 or 3,
variants), free signs. Size: the largest change of a channel's zero over the window as a
fraction of that channel's simulated peak.

Tests (:meth:`SensorDrift.checks`): ``seen_in_air`` — refitted without drift, the model is worse
on the load-free instants by at least :data:`AIR_GAIN` (χ² beyond the drift's parameters);
``explains_air`` — the drift removes at least :data:`AIR_SHARE` of what the load-free instants
show beyond the noise model; ``one_way`` — the fitted zero goes one way: on no channel does it
turn back by more than :data:`TURN_BACK` of the largest channel's excursion. Over a recording of
tens of seconds an instrument drifts one way (a warm-up, a creep); a zero that wanders (a random
walk of the amplifier) is also seen in air, but a smooth trend either leaves most of its wander
there or, following it, turns back: that is noise the noise model could not resolve from a few
seconds of air, not a drift. Curve fits of one-way drifts turn back a little (a cubic through a
sigmoid or a warm-up: up to 0.2 of the excursion). ``not_a_jump`` — the load-free instants
prefer a smooth zero to one that jumps where none of them sees it: the residual with the drift
put back, fitted there by a level and a Legendre series of any degree d ≤ 3, against a level on
each side of the cut (a re-zeroing or a moved cable during the cut, or just before contact
inside the margin of :mod:`.air`, leaves two flat levels that a drift joins through the cut);
it fails when the two levels are better by at least :data:`JUMP_MARGIN` (χ², the series' extra
coefficients counted at ln n_air each).
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.catalogue.registry import Check, Layout, Parameter, Reading, Role, Term, Variant, register
from femstudy.diagnosis.flexible import legendre_basis

NAME = "sensor_drift"
DEGREES = (1, 2, 3)
FLOOR = 0.01
#: Least χ² gain on the load-free instants (beyond the drift's parameters) that shows the drift in air.
AIR_GAIN = 10.0
#: Least share of the load-free instants' excess over the noise model that a drift removes
#: (coloured noise the noise model rates low leaves up to a quarter of that excess to a true drift).
AIR_SHARE = 0.7
#: Largest turn back of a channel's fitted zero, as a fraction of the largest channel's excursion.
TURN_BACK = 0.5
#: χ² (beyond parameters) by which two levels, one each side of the cut, must fit the load-free
#: instants better than the best smooth drift for the drift to fail ``not_a_jump``: strong evidence
#: on the BIC scale, not a preference (two levels and a line have as many coefficients, and a
#: linear drift seen through short stretches fits both about equally: docs/diagnosis.md §6).
JUMP_MARGIN = 6.0
#: Least load-free time [s] on which a drift can be seen.
MIN_AIR_S = 0.8


_BASES: dict = {}


def _basis(t: np.ndarray, lower: float, upper: float, degree: int) -> np.ndarray:
    """:func:`.legendre_basis` of the model grid, computed once per grid, window and degree (a fit
    evaluates the drift on the same grid some ten times; the grid is held with its basis, so its
    ``id`` is not reused while it is cached)."""
    key = (id(t), lower, upper, degree)
    hit = _BASES.get(key)
    if hit is None or hit[0] is not t:
        if len(_BASES) >= 16:
            _BASES.clear()
        hit = _BASES[key] = (t, legendre_basis(t, lower, upper, degree))
    return hit[1]


def window(problem) -> tuple[float, float]:
    t = problem.band.t_dec
    return float(t[0]), float(t[-1])


class SensorDrift:
    name = NAME
    role = Role.SENSOR
    floor = FLOOR
    scans = False

    def available(self, problem) -> bool:
        return True

    def variants(self, problem, residual, base) -> list[Variant]:
        return [Variant((("degree", d),), f"degree {d}") for d in DEGREES]

    def layout(self, problem, variant: Variant) -> Layout:
        d = variant.get("degree", 1)
        names = [f"{c}_P{k}" for c in problem.channels for k in range(1, d + 1)]
        n = len(names)
        return Layout(tuple(names), np.full(n, -np.inf), np.full(n, np.inf), np.zeros(n), np.zeros(n, bool))

    def term(self, problem, frame, variant, theta) -> Term:
        d = variant.get("degree", 1)
        lo, hi = window(problem)
        X = _basis(frame.t, lo, hi, d)
        n_ch = len(problem.channels)
        value = np.zeros((n_ch, frame.t.size))
        for c in range(n_ch):
            value[c] = X @ theta[c * d:(c + 1) * d]

        def derivatives() -> tuple[np.ndarray, None]:
            jac = np.zeros((n_ch, frame.t.size, theta.size))
            for c in range(n_ch):
                jac[c, :, c * d:(c + 1) * d] = X
            return jac, None

        return Term(value, derivatives)

    def curves(self, problem, fit, t: np.ndarray) -> np.ndarray:
        d = fit.spec.variant(NAME).get("degree", 1)
        lo, hi = window(problem)
        X = legendre_basis(t, lo, hi, d)
        theta = fit.block(NAME)
        return np.vstack([X @ theta[c * d:(c + 1) * d] for c in range(len(problem.channels))])

    def size(self, problem, fit) -> float:
        curves = self.curves(problem, fit, problem.band.t_dec)
        return max(float(np.ptp(curves[c])) / problem.peak(c) for c in range(len(problem.channels)))

    def checks(self, problem, fit, refit) -> list[Check]:
        air_s = float(np.count_nonzero(problem.air & problem.usable)) * float(np.median(np.diff(problem.band.t_dec)))
        if air_s < MIN_AIR_S:
            return [Check("seen_in_air", False, air_s, f"only {air_s:.1f} s of the record is surely load-free: "
                                                       f"a drift cannot be told from the cut's own trends")]
        gain = refit("without_in_air", fit)
        share = refit("air_explained", fit)
        return [Check("seen_in_air", gain >= AIR_GAIN, gain,
                      f"without the drift the load-free instants are worse by {gain:.1f} (χ² beyond the drift's "
                      f"parameters; at least {AIR_GAIN:g})"),
                Check("explains_air", share >= AIR_SHARE, share,
                      f"a smooth drift removes {100 * share:.0f} % of what the load-free instants show beyond the noise "
                      f"model (at least {100 * AIR_SHARE:g} %: the rest is a zero that wanders, not a drift)",
                      "wandering_zero"),
                self._one_way(problem, fit), self._not_a_jump(problem, fit)]

    def _one_way(self, problem, fit) -> Check:
        """``one_way``: how far the fitted zero turns back against its own change, on the channel
        where that is largest, over the largest channel's excursion."""
        lo, hi = window(problem)
        curves = self.curves(problem, fit, np.linspace(lo, hi, 401))
        excursion = float(np.ptp(curves, axis=1).max())
        oriented = curves * np.where(curves[:, -1] >= curves[:, 0], 1.0, -1.0)[:, None]
        back = float((np.maximum.accumulate(oriented, axis=1) - oriented).max())
        turn = back / excursion if excursion > 0 else 0.0
        return Check("one_way", turn <= TURN_BACK, turn,
                     f"the fitted zero turns back by {100 * turn:.0f} % of its excursion (at most {100 * TURN_BACK:g} %: "
                     f"an instrument drifts one way over a recording; a zero that comes back wanders)",
                     "wandering_zero")

    def _not_a_jump(self, problem, fit) -> Check:
        """``not_a_jump``: how much better (χ² beyond parameters) the best smooth zero of degree
        1–3 fits the load-free instants than a level on each side of the cut, both fitted there
        to the residual with the drift put back (one more level each)."""
        rows = problem.air & problem.usable
        t = problem.band.t_dec
        lo, hi = window(problem)
        drift = self.curves(problem, fit, t)
        # columns: a level, a step at contact, then P1 … P3; each channel's whitened once
        columns = np.column_stack([np.ones(t.size), (t > problem.contact_t).astype(float),
                                   legendre_basis(t, lo, hi, max(DEGREES))])
        penalty = math.log(max(np.count_nonzero(rows), 3))
        whitened = [(problem.whiten(c, problem.y[c] - fit.model[c] + drift[c], rows), problem.whiten(c, columns, rows))
                    for c in range(len(problem.channels))]

        def misfit(kept: list[int]) -> float:
            total = 0.0
            for r, A in whitened:
                coef, *_ = np.linalg.lstsq(A[:, kept], r, rcond=None)
                total += float(np.sum((r - A[:, kept] @ coef) ** 2))
            return total

        jump = misfit([0, 1])
        gain = max(jump - misfit([0, *range(2, 2 + d)]) - len(whitened) * (d - 1) * penalty for d in DEGREES)
        better = (f"two levels, one each side of the cut, fit the load-free instants better than the best smooth "
                  f"drift by {-gain:.1f}" if gain < 0 else
                  f"the best smooth drift fits the load-free instants better than two levels, one each side of the "
                  f"cut, by {gain:.1f}")
        return Check("not_a_jump", gain > -JUMP_MARGIN, gain,
                     f"{better} (χ² beyond parameters; two levels better by {JUMP_MARGIN:g} or more: the zero jumped "
                     f"where no load-free instant sees it, a re-zeroing or a moved cable, not a drift)", "zero_jump")

    def reading(self, problem, fit, context) -> Reading:
        lo, hi = window(problem)
        span = hi - lo
        t = np.linspace(lo, hi, 201)
        curves = self.curves(problem, fit, t)
        units = {"thrust_N": ("thrust", "N"), "torque_Nmm": ("torque", "N·mm")}
        params, parts = [], []
        for c, name in enumerate(problem.channels):
            word, unit = units[name]
            change = float(curves[c, -1] - curves[c, 0])
            rate = change / span
            curvature = float(np.max(np.abs(curves[c] - (curves[c, 0] + (t - lo) / span * change))))
            key = "thrust_N" if name == "thrust_N" else "torque_Nmm"
            params += [Parameter(f"{key}_per_s", round(rate, 5)), Parameter(f"{word}_change_{unit.replace('·', '')}",
                                                                                  round(change, 4)),
                       Parameter(f"{word}_departure_from_straight_{unit.replace('·', '')}", round(curvature, 4))]
            parts.append(f"the {word} reading by {change:+.3g} {unit} over {span:.1f} s ({rate:+.3g} {unit}/s"
                         + (f", bending up to {curvature:.3g} {unit} off a straight line" if curvature > 0.1 * abs(change)
                            else "") + ")")
        params.append(Parameter("duration_s", round(span, 3)))
        text = (f"The sensor zero moves smoothly, in contact and out of it: {' and '.join(parts)}. The load-free "
                f"stretches before contact and after retraction show it, which separates it from softening or "
                f"clogging. It is an instrument drift, not a cutting load; correct the recording for it before "
                f"calibrating.")
        return Reading(tuple(params), text)


register(SensorDrift())
