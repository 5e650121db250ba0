"""Thermal softening: the loads fall by H = 1 − s (1 − exp(−(t − t_c)/τ_s)) after contact t_c,
a loss that grows with time in contact rather than with depth."""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.mechanisms.registry import Mechanism, Parameter, register, significant as _r

#: Least loss by the end of the cut (fraction of the load) that counts as missing physics.
MIN_SOFTENING_LOSS = 0.05


def factor(problem: Problem, params: dict, t: np.ndarray, t_contact: float) -> np.ndarray:
    """H(t) on both cutting loads."""
    tau_s = 10.0 ** params["softening_log10_tau_s"]
    return 1.0 - params["softening_fraction"] * -np.expm1(-np.maximum(t - t_contact, 0.0) / tau_s)


def stand_in(problem: Problem, base_params: dict, plain: dict, tau_s: float) -> dict:
    """Linear stand-in per channel: the loads times the loss's growth at time constant ``tau_s``."""
    t = problem.band.t_model
    soft = -np.expm1(-np.maximum(t - (problem.simulation.contact_s + base_params["shift_s"]), 0.0) / tau_s)
    return {c: plain[c] * soft for c in problem.channels}


def seeds(problem: Problem, linearisation) -> list[dict]:
    """The fraction of the stand-in at the scanned time constant with the least misfit."""
    return [{"softening_fraction": float(np.clip(-linearisation.stand_ins["thermal_softening"], 0.02, 0.8)),
             "softening_log10_tau_s": float(math.log10(linearisation.tau_s))}]


def _cut_s(problem: Problem) -> float:
    sim = problem.simulation
    cut = sim.stop_s - sim.contact_s
    return cut if math.isfinite(cut) else problem.band.t_dec[-1] - sim.contact_s


def size(problem: Problem, p: dict) -> float:
    """The loss reached by the end of the cut, a fraction of the load."""
    return p["softening_fraction"] * -math.expm1(-_cut_s(problem) / 10 ** p["softening_log10_tau_s"])


def explain(problem: Problem, p: dict, bone_mu_w: float | None) -> tuple[dict, str]:
    """Fraction, time constant and the loss reached by the end of the cut."""
    s, tau = p["softening_fraction"], 10 ** p["softening_log10_tau_s"]
    cut = _cut_s(problem)
    if problem.simulation.stop_is_parameter:
        cut = p["stop_depth_mm"] / problem.geometry.feed_mm_s
    loss = s * -math.expm1(-cut / tau)
    params = {"fraction": _r(s), "time_constant_s": _r(tau), "loss_at_end_of_cut": _r(loss),
              "time_in_contact_s": _r(cut)}
    text = (f"From contact on, the loads fall below the simulation by a fraction that grows as "
            f"{s:.3g}·(1 − exp(−t/{tau:.3g} s)); after {cut:.1f} s of cutting they are {100 * loss:.0f} % lower. "
            f"A loss that grows with time in contact, not with depth, is the bone softening as the cut heats it.")
    return params, text


THERMAL_SOFTENING = register(Mechanism(
    name="thermal_softening",
    parameters=(Parameter("softening_fraction", 0.0, 0.95), Parameter("softening_log10_tau_s", -1.0, 1.8)),
    seeds=seeds, size=size, threshold=MIN_SOFTENING_LOSS, explain=explain, factor=factor, stand_in=stand_in))
