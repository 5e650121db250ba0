"""The two inputs of a diagnosis: the recording's cut and the simulation to compare it with."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage

from femstudy.diagnosis.baseline import ModelSimulation, TraceSimulation
from femstudy.drilling.history import DrillingConditions
from femstudy.errors import UserError, require
from femstudy.recordings.reader import Recording, read_recording

DIAGNOSED_MODELS = ("allotta", "clogging")
#: A simulated trace whose rise is further than this from the recording's is on another clock [s].
CLOCK_TOLERANCE_S = 0.4


def cut_phase(rec: Recording):
    """Contact and end of the cut, by :func:`femstudy.recordings.isolation.isolate`."""
    from femstudy.recordings.isolation import isolate

    m = rec.metadata
    return isolate(rec.time_s, rec.thrust_N, rec.torque_Nmm, rec.feed_mm_s, rec.spindle_rpm,
                   rec.drill.cone_length_mm, m.get("contact_s"), m.get("cut_end_s"), rec.name)


def cortex_thickness(rec: Recording, given: float | None, phase=None) -> float:
    """Cortex [mm]: ``given``, else the header's ``cortex_mm``, else feed × (breakthrough − contact)."""
    if given is not None:
        require(given > 0, f"--cortex-mm must be positive, got {given}")
        return float(given)
    if "cortex_mm" in rec.metadata:
        value = rec.metadata["cortex_mm"]
        require(isinstance(value, (int, float)) and value > 0,
                f"recording {rec.name}: cortex_mm = {value!r} is not a positive length in mm")
        return float(value)
    phase = phase or cut_phase(rec)
    require(phase.end_kind == "breakthrough",
            f"recording {rec.name} ends by retraction, not breakthrough, so its cortex thickness is not "
            f"measured: give --cortex-mm or '# cortex_mm = ...' in its header")
    return rec.feed_mm_s * (phase.end_s - phase.contact_s)


def read_simulation(path, rec: Recording) -> TraceSimulation:
    """A simulated trace in the recording format; its feed and speed must match the recording's."""
    keys = {"feed_mm_s": rec.feed_mm_s, "spindle_rpm": rec.spindle_rpm}
    sim = read_recording(path, keys, override_header=True)
    for key, value in keys.items():
        for note in sim.notes:
            if note.startswith(f"{key} = ") and "overrides" in note:
                raise UserError(f"simulation {sim.name} was computed for {key} = {sim_header_value(note)} but the "
                                f"recording {rec.name} has {key} = {value:g}")
    return on_recording_clock(TraceSimulation.from_recording(sim, rec.spindle_rpm), rec)


def _rise_time_s(t: np.ndarray, F: np.ndarray, window: int) -> float:
    """First time the thrust, averaged over ``window`` samples and measured from its level at
    the start, exceeds a tenth of its peak."""
    smooth = ndimage.uniform_filter1d(F, max(window, 1))
    rise = smooth - np.median(smooth[: max(smooth.size // 20, 1)])
    return float(t[int(np.argmax(rise > 0.1 * rise.max()))])


def on_recording_clock(sim: TraceSimulation, rec: Recording) -> TraceSimulation:
    """The trace itself when its clock is the recording's, else moved onto it.

    A trace whose rise (10 % of peak) is more than ``CLOCK_TOLERANCE_S`` from the recording's
    runs on another clock (an FE history usually starts at contact): it is shifted to put its
    contact at the contact that :func:`cut_phase` detects, and a note says so. Smaller offsets
    are left to the alignment."""
    window = int(round(0.05 * rec.sample_rate_hz))
    offset = _rise_time_s(rec.time_s, rec.thrust_N, window) - _rise_time_s(sim.time_s, sim.thrust_N, 1)
    if abs(offset) <= CLOCK_TOLERANCE_S:
        return sim
    shift = cut_phase(rec).contact_s - sim.contact_s
    moved = replace(sim, time_s=sim.time_s + shift)
    moved.note = (f"{sim.label} runs on another clock: shifted by {shift:+.3f} s to put its contact at the "
                  f"recording's detected contact")
    return moved


def sim_header_value(note: str) -> str:
    """The header's value in a reader note '<key> = <new> from the command line overrides <old> in the header'."""
    return note.split(" overrides ", 1)[1].rsplit(" in the header", 1)[0]


def feed_stop_s(rec: Recording, after_s: float) -> float:
    """When the feed stopped in cancellous bone, after ``after_s`` (the cone through the cortex).

    The small cancellous cutting load vanishes within one revolution when the feed stops: the
    thrust, averaged over one revolution (ripple gone), is fitted over [after_s, end] by a
    level + a linear trend (a drifting sensor) + a downward step at t_s, for t_s on a 10 ms
    grid; the least-squares t_s wins. Without such a step (the drill stopped at breakthrough)
    the answer is ``after_s``."""
    t, F = rec.time_s, rec.thrust_N
    revolution = max(1, int(round(60.0 / rec.spindle_rpm * rec.sample_rate_hz)))
    smooth = ndimage.uniform_filter1d(F, revolution)
    step = max(1, int(round(0.01 * rec.sample_rate_hz)))
    keep = np.flatnonzero(t >= after_s)[::step]
    if keep.size < 10:
        return after_s
    tt, ff = t[keep], smooth[keep]
    best, best_t = np.inf, after_s
    for k in range(2, tt.size - 2):
        A = np.column_stack([np.ones_like(tt), tt - tt[0], (np.arange(tt.size) < k).astype(float)])
        coef, *_ = np.linalg.lstsq(A, ff, rcond=None)
        sse = float(np.sum((A @ coef - ff) ** 2))
        if coef[2] > 0 and sse < best:
            best, best_t = sse, float(tt[k])
    return best_t


def model_simulation(rec: Recording, model: str, bone, cortex_mm: float | None) -> tuple[ModelSimulation, float]:
    """Load model ``model`` for the recording's conditions, from its detected contact to its stop."""
    require(model in DIAGNOSED_MODELS, f"--model must be one of {', '.join(DIAGNOSED_MODELS)}, got '{model}'")
    phase = cut_phase(rec)
    cortex = cortex_thickness(rec, cortex_mm, phase)
    cond = DrillingConditions(rec.feed_mm_s, rec.spindle_rpm, cortex, bone, rec.drill)
    stop_s = phase.end_s
    if phase.end_kind == "breakthrough":  # the drill went on into cancellous bone
        stop_s = feed_stop_s(rec, phase.end_s + rec.drill.cone_length_mm / rec.feed_mm_s)
    stop_depth = rec.feed_mm_s * (stop_s - phase.contact_s)
    sim = ModelSimulation(model, cond, phase.contact_s, stop_depth,
                          with_torque=rec.torque_Nmm is not None,
                          max_depth_mm=rec.feed_mm_s * (rec.time_s[-1] - phase.contact_s))
    return sim, cortex
