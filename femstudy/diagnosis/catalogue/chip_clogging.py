"""Chip clogging: an excess load that grows with the depth of the chip column and ends at exit.

Signature (what any plausible form of it does, thesis §3.2): the chips packed in the flutes are
pushed up a column that lengthens with depth in cortex, so the excess

- is zero until the tip cone is engaged and **grows monotonically with depth** z past full
  engagement (any law: the thesis's F_o(e^{pz} − 1), a power, a late onset, an S-curve, a
  saturating rise), frozen when the tip leaves the cortex;
- loads **both channels**: the wall friction that holds the column back makes a torque
  k_T = R μ_w l_w / M per newton of excess thrust (Eq 3.19 over Eq 3.16), between
  :data:`MIN_TORQUE_RATIO` and :data:`MAX_TORQUE_RATIO` drill radii;
- **ends at exit**: after breakthrough it leaves (with the cone as it clears the cortex, or over
  some time as the flutes empty), or part of it stays packed in the cortical hole, never more
  than what was there; and it is pushed only while the drill feeds.

Fit: before breakthrough ΔF = F_o Σ β_j I_j(z), with I_j the monotone I-splines of
:mod:`..flexible` over the column, β_j ≥ 0; after it
ΔF = F_o Σ ρ_j w_j(t), ρ_j ≥ 0, the w_j falling from 1: the share of the cone still in cortex,
1 − I_j(t − t_b) over the rest of the cut (any monotone decrease), and 1 (what stays);
ΔT = k_T ΔF with torque. The splines have 3, 6 or 12 intervals over the column and half as many
after breakthrough (variants, :data:`RESOLUTIONS`: the coarsest that fits pays for the fewest
coefficients).
Its size is the rise of the thrust by breakthrough, ΔF/F_o at the deepest column; after
breakthrough Σ ρ_j may not exceed :data:`MAX_RETAINED` times it (``ends_at_exit``).

Tests (:meth:`ChipClogging.checks`): ``grows_with_depth`` — the same splines with coefficients of
either sign (an excess free to fall as well as rise) gain at most :data:`MONOTONE_MARGIN` χ² or
:data:`MONOTONE_SHARE` of what the clogging gains (the misfit of another mechanism's form, a
pulse, a layer, is not monotone in depth, and a flexible monotone rise should not be what soaks
it up); ``torque_follows`` — with torque, k_T/R within the wall friction's range;
``ends_at_exit`` — what stays after breakthrough.

Reading: the equivalent growth exponent p = ln(F(z_bt)/F_o)/z_bt of the total thrust (the
thesis's form has exactly this p) is inverted for the flute friction with p = ηMD/S (Eq 3.13)
and M = μ_f · (l_f + l_h + l_r + l_w μ_w sin θ) (Eq 3.14, :func:`femstudy.drilling.clogging.friction_factor`
with μ_f = 1); with torque, μ_w comes from k_T = R μ_w l_w / M, otherwise from the bone set.
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.catalogue.registry import (Check, Layout, Parameter, Reading, Role, Term, Variant,
                                                  proportional_term, register)
from femstudy.diagnosis.flexible import monotone_basis
from femstudy.drilling.clogging import friction_factor

NAME = "chip_clogging"
#: Intervals of the monotone spline over the column, one variant each, simplest first; after
#: breakthrough half as many.
RESOLUTIONS = (3, 6, 12)
#: Torque per newton of excess thrust that wall friction allows, in drill radii: k_T/R = μ_w l_w/M,
#: from near 0 (μ_w → 0) to about 20 (μ_f = 0.02 with μ_w = 0.6 on the thesis's drill).
MIN_TORQUE_RATIO = 0.05
MAX_TORQUE_RATIO = 20.0
#: Least rise of the thrust by breakthrough (fraction of F_o) that counts.
FLOOR = 0.05
#: What the excess may gain by falling as well as rising with depth (χ², or this share of what the
#: clogging gains): more, and the excess is not a chip column's.
MONOTONE_MARGIN = 10.0
MONOTONE_SHARE = 0.1
#: What may stay packed after breakthrough, as a multiple of the excess at breakthrough.
MAX_RETAINED = 1.5


def cone_share(depth_mm: np.ndarray, cortex_mm: float, cone_mm: float) -> np.ndarray:
    """The share of the tip cone still in cortex: 1 until the tip reaches the cortex's far side,
    falling to 0 as the cone leaves it."""
    inside = np.minimum(depth_mm, cortex_mm)
    return np.clip(inside - np.maximum(depth_mm - cone_mm, 0.0), 0.0, cone_mm) / cone_mm if cone_mm > 0 else 1.0


def column_z(problem, depth_mm: np.ndarray) -> np.ndarray:
    """Chip column past full engagement, in diameters, frozen when the tip leaves the cortex."""
    g = problem.geometry
    return np.maximum(np.minimum(depth_mm, g.cortex_mm) - g.cone_mm, 0.0) / g.diameter_mm


def wall_friction(growth_exponent: float, torque_ratio_mm: float | None, mu_w_bone: float | None, drill) -> dict:
    """μ_f (and μ_w) from the growth exponent p [1/diameter] and the torque ratio k_T [mm]
    (Eqs 3.13, 3.14, 3.19): M = pS/(ηD); with k_T, μ_w = k_T M/(R l_w), else μ_w from the bone
    set; μ_f = M / friction_factor(1, μ_w)."""
    M = growth_exponent * drill.flute_area_mm2 / (drill.eta * drill.diameter_mm)
    out = {"friction_factor_M_mm": M}
    if torque_ratio_mm is not None and torque_ratio_mm > 0:
        mu_w, source = torque_ratio_mm * M / (drill.radius_mm * drill.wall_mm), "the torque gain k_T = R μ_w l_w / M"
    elif mu_w_bone is not None:
        mu_w, source = mu_w_bone, "the bone set at this feed and speed"
    else:
        return out
    if M > 0:
        out.update(mu_w=mu_w, mu_f=M / friction_factor(1.0, mu_w, drill), mu_w_source=source)
    return out


class ChipClogging:
    name = NAME
    role = Role.LOAD
    floor = FLOOR
    scans = False

    def available(self, problem) -> bool:
        return problem.clogging_possible

    def variants(self, problem, residual, base) -> list[Variant]:
        return [Variant((("intervals", n),), f"{n} intervals") for n in RESOLUTIONS]

    @staticmethod
    def intervals(variant: Variant) -> int:
        return variant.get("intervals", RESOLUTIONS[-1])

    def _leaving(self, problem, intervals: int) -> tuple[str, ...]:
        """Names of the after-breakthrough columns (none if the simulation does not break through)."""
        if not problem.breaks_through:
            return ()
        return (("after_cone",) + tuple(f"after_leaving_{j}" for j in range(max(intervals // 2, 1) + 2))
                + ("after_stays",))

    def layout(self, problem, variant: Variant) -> Layout:
        n = self.intervals(variant)
        k = n + 2
        names = [f"rise_{j}" for j in range(k)]
        lower, upper, start, counted = [-5.0 if variant.get("signed") else 0.0] * k, [5.0] * k, [0.0] * k, [True] * k
        for name in self._leaving(problem, n):
            names.append(name)
            lower.append(0.0), upper.append(5.0), start.append(0.0), counted.append(True)
        if problem.has_torque:
            R = problem.geometry.drill.radius_mm
            names.append("torque_per_thrust_mm")
            lower.append(0.0), upper.append(MAX_TORQUE_RATIO * R), start.append(0.5 * R), counted.append(False)
        return Layout(tuple(names), np.array(lower), np.array(upper), np.array(start), np.array(counted))

    def _columns(self, problem, frame, n: int) -> np.ndarray:
        """Thrust columns per coefficient (instants × k), in N per unit coefficient."""
        depth = frame.depth_mm
        g = problem.geometry
        z = column_z(problem, depth)
        basis = monotone_basis(z, 0.0, max(problem.clogging_span, 1e-6), n)
        weight = problem.initial_force_N * frame.fall
        if not self._leaving(problem, n):
            return basis * weight[:, None]
        after = depth > g.cortex_mm
        since = np.clip(frame.tau - (frame.contact_tau_s + g.cortex_mm / g.feed_mm_s), 0.0, None)
        remaining = max(problem.cut_s - g.cortex_mm / g.feed_mm_s, 0.05)
        falling = 1.0 - monotone_basis(since, 0.0, remaining, max(n // 2, 1))
        leaving = [cone_share(depth, g.cortex_mm, g.cone_mm)] + list(falling.T) + [np.ones_like(since)]
        columns = [basis * (~after * weight)[:, None]] + [(w * after * weight)[:, None] for w in leaving]
        return np.hstack(columns)

    def term(self, problem, frame, variant, theta) -> Term:
        return proportional_term(problem, self._columns(problem, frame, self.intervals(variant)), theta)

    def after(self, problem, fit) -> float:
        """The excess just after breakthrough, ΔF/F_o (every w_j is 1 there)."""
        n = self.intervals(fit.spec.variant(NAME))
        return float(np.sum(fit.block(NAME)[n + 2:n + 2 + len(self._leaving(problem, n))]))

    def rise(self, problem, fit) -> float:
        """ΔF/F_o at the deepest column (by breakthrough when the simulation breaks through)."""
        coef = fit.block(NAME)[:self.intervals(fit.spec.variant(NAME)) + 2]
        return float(np.sum(coef))   # every I-spline is 1 at the end of the column

    def size(self, problem, fit) -> float:
        return self.rise(problem, fit)

    def torque_ratio(self, problem, fit) -> float | None:
        return fit.value(f"{NAME}.torque_per_thrust_mm") if problem.has_torque else None

    def checks(self, problem, fit, refit) -> list[Check]:
        rise = self.rise(problem, fit)
        gain, signed = refit("gain", fit), refit("signed", fit)
        allowed = max(MONOTONE_MARGIN, MONOTONE_SHARE * gain)
        out = [Check("grows_with_depth", signed <= allowed, signed,
                     f"an excess free to fall as well as rise with depth gains {signed:.1f} more (χ²; at most "
                     f"{allowed:.1f}: a chip column's grows)")]
        if problem.has_torque:
            R = problem.geometry.drill.radius_mm
            ratio = self.torque_ratio(problem, fit) / R
            ok = MIN_TORQUE_RATIO <= ratio < 0.999 * MAX_TORQUE_RATIO
            out.append(Check("torque_follows", ok, ratio,
                             f"the torque rises with the thrust by {ratio:.2g} drill radii per newton "
                             f"(wall friction allows {MIN_TORQUE_RATIO:g}-{MAX_TORQUE_RATIO:g})"))
        if self._leaving(problem, self.intervals(fit.spec.variant(NAME))):
            after = self.after(problem, fit)
            ok = after <= MAX_RETAINED * max(rise, 1e-9)
            out.append(Check("ends_at_exit", ok, after / max(rise, 1e-9),
                             f"at breakthrough the excess after it is {after / max(rise, 1e-9):.2f} times the excess "
                             f"before (at most {MAX_RETAINED:g}: the packed chips leave, they do not grow)"))
        return out

    def reading(self, problem, fit, context) -> Reading:
        g, sim = problem.geometry, problem.simulation
        z_max = problem.clogging_span
        rise = self.rise(problem, fit)
        scale = fit.value("thrust_N_scale", 1.0)
        F_o = problem.initial_force_N * scale
        excess = F_o * rise
        deepest = sim.contact_s + min(g.cortex_mm, problem.deepest_mm) / g.feed_mm_s
        simulated = float(sim.loads(np.array([deepest]), problem.stop_s)[0][0]) * scale
        total = math.log(max(simulated + excess, 1e-12) / F_o) / z_max if z_max > 0 else 0.0
        own = math.log(max(simulated, 1e-12) / F_o) / z_max if z_max > 0 else 0.0
        n = self.intervals(fit.spec.variant(NAME))
        coef = fit.block(NAME)[:n + 2]
        z = np.linspace(0.0, z_max, 41)
        curve = monotone_basis(z, 0.0, max(z_max, 1e-6), n) @ coef
        half = float(np.interp(0.5 * rise, curve, z)) / z_max if rise > 0 and z_max > 0 else 0.5
        shape = ("accelerating with depth" if half > 0.62 else "rising early and levelling off" if half < 0.42
                 else "rising about steadily with depth")
        ratio = self.torque_ratio(problem, fit)
        drill = g.drill
        friction = wall_friction(total, ratio if abs(own) < 0.01 else None, context.get("bone_mu_w"), drill)
        params = [Parameter("rise_at_breakthrough", round(rise, 4)), Parameter("excess_thrust_at_breakthrough_N", round(excess, 4)),
                  Parameter("initial_force_N", round(F_o, 4)),
                  Parameter("growth_exponent_per_diameter", round(math.log1p(rise) / z_max, 4) if z_max > 0 else 0.0),
                  Parameter("total_growth_exponent", round(total, 4)),
                  Parameter("depth_past_full_engagement_diameters", round(z_max, 4)),
                  Parameter("half_rise_at_column_fraction", round(half, 3)), Parameter("shape", shape)]
        if self._leaving(problem, n):
            stays = fit.value(f"{NAME}.after_stays")
            params.append(Parameter("retained_after_breakthrough", round(stays / max(rise, 1e-9), 3)))
        torque_text = ""
        if ratio is not None:
            params.append(Parameter("torque_gain_Nmm_per_N", round(ratio, 4)))
            torque_text = (f" The torque rises with it, {ratio:.3g} N·mm per newton of extra thrust "
                           f"({ratio * excess:.3g} N·mm at breakthrough).")
        friction_text = ""
        if "mu_f" in friction:
            params += [Parameter("friction_factor_M_mm", round(friction["friction_factor_M_mm"], 4)),
                       Parameter("implied_mu_f", round(friction["mu_f"], 4)), Parameter("mu_w_used", round(friction["mu_w"], 4)),
                       Parameter("mu_w_source", friction["mu_w_source"])]
            friction_text = (f" Read with the thesis's law (F = F_o e^(pz), p = ηMD/S, Eqs 3.13-3.16), the total "
                             f"growth p = {total:.3g} per diameter gives M = {friction['friction_factor_M_mm']:.3g} mm and, "
                             f"with μ_w = {friction['mu_w']:.3g} from {friction['mu_w_source']}, an implied flute friction "
                             f"μ_f ≈ {friction['mu_f']:.3g}.")
        text = (f"After full engagement the thrust rises above the simulation with the depth of the chip column, "
                f"{shape}: +{100 * rise:.0f} % of F_o = {F_o:.3g} N (+{excess:.3g} N) by breakthrough, "
                f"{z_max:.2f} diameters past full engagement.{torque_text} This is chip clogging: bone chips "
                f"packing in the flutes (thesis §3.2), missing from the simulation.{friction_text}")
        return Reading(tuple(params), text)


register(ChipClogging())
