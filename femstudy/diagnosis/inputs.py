"""The two inputs of a diagnosis: the recording's cut and the simulation to compare it with.

With a simulated trace, timing and geometry come from the trace (:mod:`.timing`): it is put
on the recording's clock by correlation, and its breakthrough gives the cortex. Nothing here
refuses a well-formed pair: a value that cannot be measured is estimated, and a note says how.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage

from femstudy.diagnosis.baseline import ModelSimulation, TraceSimulation
from femstudy.diagnosis.timing import clock_offset_s, trace_events
from femstudy.drilling import registry
from femstudy.drilling.history import DrillingConditions
from femstudy.errors import UserError, require
from femstudy.recordings.reader import Recording, read_recording

#: A trace whose best correlation lag exceeds this runs on a clock of its own [s].
CLOCK_TOLERANCE_S = 0.3


def cut_phase(rec: Recording):
    """Contact and end of the cut, by :func:`femstudy.recordings.isolation.isolate`."""
    from femstudy.recordings.isolation import isolate

    m = rec.metadata
    return isolate(rec.time_s, rec.thrust_N, rec.torque_Nmm, rec.feed_mm_s, rec.spindle_rpm,
                   rec.drill.cone_length_mm, m.get("contact_s"), m.get("cut_end_s"), rec.name)


def _header_cortex(rec: Recording) -> float | None:
    if "cortex_mm" not in rec.metadata:
        return None
    value = rec.metadata["cortex_mm"]
    require(isinstance(value, (int, float)) and value > 0,
            f"recording {rec.name}: cortex_mm = {value!r} is not a positive length in mm")
    return float(value)


def _given(given: float | None) -> float | None:
    if given is not None:
        require(given > 0, f"--cortex-mm must be positive, got {given}")
        return float(given)
    return None


def cortex_thickness(rec: Recording, given: float | None, phase=None) -> tuple[float, list[str]]:
    """Cortex [mm] of a recording diagnosed without a simulated trace, and notes on how it was
    found: ``given``, else the header's ``cortex_mm``, else feed × (breakthrough − contact) from
    the isolation, else — the cut ends by retraction, or its breakthrough is not seen — the
    depth the drill reached, feed × (end − contact), which the note says."""
    value = _given(given)
    if value is None:
        value = _header_cortex(rec)
    if value is not None:
        return value, []
    phase = phase or cut_phase(rec)
    depth = rec.feed_mm_s * (phase.end_s - phase.contact_s)
    if phase.end_kind == "breakthrough":
        return depth, []
    return depth, [f"no breakthrough is seen in {rec.name} (the cut ends by retraction, or clogging holds the "
                   f"loads until the drill stops): the cortex is taken as the depth reached, {depth:.2f} mm "
                   f"(feed x cut duration); give --cortex-mm if it is known"]


def trace_cortex(sim: TraceSimulation, rec: Recording, given: float | None) -> tuple[float, list[str]]:
    """Cortex [mm] for a diagnosis against a simulated trace: ``given``, else the recording's
    header, else the trace's breakthrough (:mod:`.timing`), else the depth the trace reaches
    (it does not break through, so clogging grows to its end), with a note."""
    value = _given(given)
    if value is None:
        value = _header_cortex(rec)
    if value is not None:
        return value, []
    events = sim.events
    if events.cortex_mm is not None and events.cortex_mm > 0:
        return events.cortex_mm, []
    depth = max(events.depth_reached_mm, 1e-3)
    return depth, [f"the simulation does not break through the cortex: the cortex is taken as at least the depth it "
                   f"reaches, {depth:.2f} mm"]


def read_trace(path, rec: Recording) -> TraceSimulation:
    """A simulated trace in the recording format, on its own clock; its feed and speed must match
    the recording's."""
    keys = {"feed_mm_s": rec.feed_mm_s, "spindle_rpm": rec.spindle_rpm}
    sim = read_recording(path, keys, override_header=True)
    for key, value in keys.items():
        for note in sim.notes:
            if note.startswith(f"{key} = ") and "overrides" in note:
                raise UserError(f"simulation {sim.name} was computed for {key} = {sim_header_value(note)} but the "
                                f"recording {rec.name} has {key} = {value:g}")
    return TraceSimulation.from_recording(sim, rec.spindle_rpm)


def read_simulation(path, rec: Recording) -> TraceSimulation:
    """A simulated trace in the recording format, placed on the recording's clock, with its events."""
    return with_events(on_recording_clock(read_trace(path, rec), rec)[0], rec)


def with_events(sim: TraceSimulation, rec: Recording) -> TraceSimulation:
    """The trace with its events (contact, full engagement, breakthrough, stop) attached."""
    sim.events = trace_events(sim.time_s, sim.thrust_N, sim.contact_s, sim.stop_s, rec.feed_mm_s,
                              rec.spindle_rpm, rec.drill.cone_length_mm)
    return sim


def on_recording_clock(sim: TraceSimulation, rec: Recording) -> tuple[TraceSimulation, tuple[float, ...]]:
    """The trace itself when its clock is the recording's, else moved onto it; and each channel's
    rate correlation with the recording there (its sign is the channel's polarity, :mod:`.sanity`).

    The lag comes from the correlation of the two (:func:`.timing.clock_offset_s`), which needs
    no detection of the cut in the recording. A lag within ``CLOCK_TOLERANCE_S`` is left to the
    alignment; a larger one means the trace runs on a clock of its own (an FE history usually
    starts at contact): it is moved by the lag, and a note says so."""
    channels = [rec.thrust_N] + ([rec.torque_Nmm] if rec.torque_Nmm is not None and sim.has_torque else [])
    lag, value, correlations = clock_offset_s(rec.time_s, channels, sim, rec.spindle_rpm)
    if abs(lag) <= CLOCK_TOLERANCE_S:
        return sim, correlations
    moved = replace(sim, time_s=sim.time_s + lag)
    moved.note = (f"{sim.label} runs on another clock: moved by {lag:+.3f} s, where it correlates best with the "
                  f"recording (rate correlation {value:.3f})")
    return moved, correlations


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


def model_simulation(rec: Recording, model: str, bone, cortex_mm: float | None) -> tuple[ModelSimulation, float, list]:
    """Load model ``model`` for the recording's conditions, from its detected contact to its
    stop; returns it, the cortex [mm] and notes on how the cortex was found."""
    registry.get(model, "diagnosis")
    phase = cut_phase(rec)
    cortex, notes = cortex_thickness(rec, cortex_mm, phase)
    cond = DrillingConditions(rec.feed_mm_s, rec.spindle_rpm, cortex, bone, rec.drill)
    stop_s = phase.end_s
    if phase.end_kind == "breakthrough":  # the drill went on into cancellous bone
        stop_s = feed_stop_s(rec, phase.end_s + rec.drill.cone_length_mm / rec.feed_mm_s)
    stop_depth = rec.feed_mm_s * (stop_s - phase.contact_s)
    sim = ModelSimulation(model, cond, phase.contact_s, stop_depth,
                          with_torque=rec.torque_Nmm is not None,
                          max_depth_mm=rec.feed_mm_s * (rec.time_s[-1] - phase.contact_s))
    return sim, cortex, notes
