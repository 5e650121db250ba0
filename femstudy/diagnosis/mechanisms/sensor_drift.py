"""Sensor drift: r_F t and r_T t on the readings over the whole recording, in and out of contact
(the rates fitted linearly; no nonlinear parameter)."""

from __future__ import annotations

import numpy as np

from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.mechanisms.registry import LinearTerm, Mechanism, register, significant as _r

#: Least drift over the recording (fraction of the peak simulated load) that counts as missing
#: physics: a drift shows outside the cut too, so its floor is low.
MIN_DRIFT_FRACTION = 0.001


def size(problem: Problem, p: dict) -> float:
    """The drift over the compared span, a fraction of the channel's peak simulated load (the
    larger of the channels)."""
    peak = max(float(np.max(np.abs(problem.simulation.loads(problem.band.t_model - p["shift_s"])[0]))), 1e-9)
    span = problem.band.t_dec[-1] - problem.band.t_dec[0]
    fractions = [abs(p["thrust_N_drift_per_s"]) * span / peak]
    if "torque_Nmm_drift_per_s" in p:
        torque = problem.simulation.loads(problem.band.t_model - p["shift_s"])[1]
        fractions.append(abs(p["torque_Nmm_drift_per_s"]) * span / max(float(np.max(np.abs(torque))), 1e-9))
    return max(fractions)


def explain(problem: Problem, p: dict, bone_mu_w: float | None) -> tuple[dict, str]:
    """Drift rates and the change over the compared span, per channel."""
    span = float(problem.band.t_dec[-1] - problem.band.t_dec[0])
    rate_F = p["thrust_N_drift_per_s"]
    params = {"thrust_N_per_s": _r(rate_F), "thrust_change_N": _r(rate_F * span), "duration_s": _r(span)}
    parts = [f"the thrust reading drifts by {rate_F:+.3g} N/s ({rate_F * span:+.3g} N over {span:.1f} s)"]
    if "torque_Nmm_drift_per_s" in p:
        rate_T = p["torque_Nmm_drift_per_s"]
        params.update({"torque_Nmm_per_s": _r(rate_T), "torque_change_Nmm": _r(rate_T * span)})
        parts.append(f"the torque reading by {rate_T:+.3g} N·mm/s ({rate_T * span:+.3g} N·mm)")
    text = (f"The sensor zero moves steadily, in contact and out of it: {' and '.join(parts)}. The load-free "
            f"samples before contact and after retraction show it, which separates it from softening or "
            f"clogging. It is an instrument drift, not a cutting load; correct the recording for it before "
            f"calibrating.")
    return params, text


SENSOR_DRIFT = register(Mechanism(
    name="sensor_drift", parameters=(),
    seeds=lambda problem, linearisation: [{}], size=size, threshold=MIN_DRIFT_FRACTION, explain=explain,
    linear=(LinearTerm("{channel}_drift_per_s", column=lambda problem: problem.ramp),)))
