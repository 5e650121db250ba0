"""The drill's loads of one sample: the case's loading with the load inputs changed.

A sample's operating point is the case's with its feed, spindle speed and drilled depth; its
friction is the bone set's power law at that (f, N) (or the case's fixed μ) times the μ factors;
its loads are the case's load model on the case's time grid, times ``drilling.load_scale`` and
the F_o factor (F_o scales both the cutting and the chip-evacuation parts, Eqs 3.16/3.19).
Units: mm, s, N, N·mm.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from femstudy.drilling import DrillingConditions, evaluate
from femstudy.study.loading import CaseLoading


def sample_conditions(base: CaseLoading, values: dict) -> DrillingConditions:
    """The operating point of a sample (``values``: input name → value; missing ones nominal)."""
    c = base.conditions
    feed = float(values.get("feed_mm_s", c.feed_mm_s))
    spindle = float(values.get("spindle_rpm", c.spindle_rpm))
    depth = float(values.get("depth_mm", c.cortex_mm))
    mu_f, mu_w = c.friction_override or c.bone.friction(feed, spindle)
    friction = (mu_f * float(values.get("mu_f_factor", 1.0)), mu_w * float(values.get("mu_w_factor", 1.0)))
    return DrillingConditions(feed, spindle, depth, c.bone, c.drill, friction)


def sample_loading(base: CaseLoading, values: dict) -> CaseLoading:
    """The sample's loading on the case's time grid, built as :func:`femstudy.case_loading`
    builds the case's (the same model, grid and scaling)."""
    cond = sample_conditions(base, values)
    k = base.scale * float(values.get("cutting_force_factor", 1.0))
    dynamic = evaluate(base.model, cond, base.times_s)
    dynamic = replace(dynamic, thrust_N=k * dynamic.thrust_N, torque_Nmm=k * dynamic.torque_Nmm)
    thrust, torque = cond.static_allotta()
    return CaseLoading(cond, cond.cortex_mm, dynamic, k * thrust, k * torque, base.model, k)


def amplitudes(base: CaseLoading, samples: list[dict]) -> np.ndarray:
    """(n_samples, n_steps, 2) thrust [N] and torque [N·mm] of every sample's dynamic loading."""
    out = np.empty((len(samples), len(base.times_s), 2))
    for k, values in enumerate(samples):
        dyn = sample_loading(base, values).dynamic
        out[k, :, 0], out[k, :, 1] = dyn.thrust_N, dyn.torque_Nmm
    return out
