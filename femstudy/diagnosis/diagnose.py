"""Diagnose one recording against one simulation: locate, explain, model, show the improvement.

Steps (each in its module): the inputs, with timing and geometry from the simulation
(:mod:`.inputs`, :mod:`.timing`); the analysis band, the alignment and the fitted noise model
(:mod:`.prepare`, :mod:`.noise`); the mismatch intervals of the aligned simulation
(:mod:`.locate`); fits of every subset of the four mechanisms (:mod:`.fit`); selection
(:mod:`.select`); what the best model leaves unexplained and the confidences
(:mod:`.openworld`, :mod:`.verdict`); held-out R² (:mod:`.heldout`); the physical reading
of the named parameters (:mod:`.explain`).

Calibration: when the selected model still leaves more than noise (χ² test p ≤ RESIDUAL_P)
and a scale on the modelled loads would explain part of what it, or the simulation alone,
leaves (:func:`scale_helps`; a mechanism fitted first can absorb most of a scale error),
everything is refitted with a scale on each channel's simulated cutting load (a simulation
whose cutting energy is off by a few percent is otherwise "explained" by softening or
clogging). The rescaled family is kept when its selected model has a BIC lower by
MIN_DELTA_BIC, on the data's own noise level. The scale is not admitted from the start
because it makes slow softening and clogging nearly interchangeable (both are close to
linear in time over a cut, and the scale removes the anchor the initial force provides).
"""

from __future__ import annotations

import logging
import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from femstudy.diagnosis import explain, heldout, inputs, openworld, report
from femstudy.diagnosis.baseline import ModelSimulation, TraceSimulation
from femstudy.diagnosis.findings import ChannelFit, MismatchInterval, Scores, Timing, TraceEventTimes
from femstudy.diagnosis.fit import Fit, fit_all, fit_each, seeds
from femstudy.diagnosis.locate import mismatch_intervals
from femstudy.diagnosis.mechanisms import Problem
from femstudy.diagnosis.prepare import align, build_problem, cut_window, restate, with_noise
from femstudy.diagnosis.result import DiagnosisResult
from femstudy.diagnosis.select import MIN_DELTA_BIC, RESIDUAL_P, Selection, select
from femstudy.diagnosis.verdict import decide
from femstudy.diagnosis.workers import fitter
from femstudy.drilling.friction import BoneSet, load_bone_set
from femstudy.errors import require
from femstudy.recordings.reader import Recording, read_recording

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Diagnosis(DiagnosisResult):
    """The result of :func:`diagnose`: everything ``femstudy diagnose`` reports (the fields are
    :class:`.result.DiagnosisResult`'s).

    :meth:`to_json` is the JSON contract (docs/diagnosis.md), :meth:`summary` the printed
    text and :meth:`write` the files.
    """

    def summary(self) -> str:
        """The printed summary (inputs, noise, timing, mechanisms, unexplained, fit, residual test)."""
        return report.summary_text(self)

    def write(self, json_path=None, plot_path=None, report_dir=None) -> list[Path]:
        """Write the JSON contract, the overlay/residual figure and the report folder (report.md,
        overlay.png, residuals.png, diagnosis.json), each atomically; returns what was written.

        Examples
        --------
        >>> d.write(json_path="d.json", report_dir="report")  # doctest: +SKIP
        [PosixPath('d.json'), PosixPath('report/report.md')]
        """
        written = []
        if json_path is not None:
            report.write_json(json_path, self)
            written.append(Path(json_path))
        if plot_path is not None:
            report.plot(plot_path, self)
            written.append(Path(plot_path))
        if report_dir is not None:
            report.write_report(report_dir, self, self.summary())
            written.append(Path(report_dir) / "report.md")
        return written


def summarise_fit(problem: Problem, baseline: Fit, improved: Fit, fits_of=fit_each) -> dict[str, ChannelFit]:
    """R² and RMSE of the smoothed recording over the cutting phase, per channel: in-sample
    (``r2``) and held out (``r2_heldout``, blocked folds, :mod:`.heldout`)."""
    window = cut_window(problem, baseline)
    if np.count_nonzero(window) < 3:
        window = np.ones_like(window)
    predictions = {label: heldout.held_out_predictions(problem, fit, window, fits_of)
                   for label, fit in (("baseline", baseline), ("improved", improved))}
    out = {}
    t = problem.band.t_dec[window]
    for c, name in enumerate(problem.channels):
        y = problem.y[c, window]
        scores = {}
        for label, fit in (("baseline", baseline), ("improved", improved)):
            r = y - fit.model[c, window]
            scores[label] = Scores(round(heldout.r2(y, fit.model[c, window]), 4),
                                   round(heldout.r2(y, predictions[label][c, window]), 4),
                                   round(float(np.sqrt(np.mean(r ** 2))), 4))
        out[name] = ChannelFit(scores["baseline"], scores["improved"], (round(float(t[0]), 3), round(float(t[-1]), 3)))
    return out


def fit_and_select(problem: Problem, start_params: dict, fits_of=fit_each) -> tuple[dict, Selection]:
    """Every subset fitted from the seeds and the aligned parameters, then selected."""
    fits = fit_all(problem, start_params, seeds(problem, start_params), fits_of)
    return fits, select(problem, fits, fits_of)


#: Least scale error (fraction) for which the calibrated family is fitted.
MIN_SCALE_ERROR = 0.01


def scale_helps(problem: Problem, fit: Fit, inflation: np.ndarray) -> bool:
    """Whether a scale on each channel's modelled load explains the residual of ``fit``: BIC
    gain (GLS, misfit-inflated) of at least ``MIN_DELTA_BIC`` and a scale error of at least
    ``MIN_SCALE_ERROR`` in some channel."""
    _, loads = openworld.modelled_loads(problem, fit.params)
    columns = problem.band.smooth_model(np.vstack(loads))
    gain, big = 0.0, False
    for c in range(len(problem.channels)):
        x = problem.whiten(c, columns[c])
        r = problem.whiten(c, problem.y[c] - fit.model[c])
        norm = float(x @ x)
        if norm <= 0:
            continue
        gain += float(x @ r) ** 2 / norm / inflation[c]
        big = big or abs(float(x @ r) / norm) >= MIN_SCALE_ERROR
    return big and gain - len(problem.channels) * math.log(problem.y.size) >= MIN_DELTA_BIC


def plain_bic(problem: Problem, fit: Fit) -> float:
    """BIC on the data's own noise level (no misfit inflation), comparable across calibrations."""
    n_eff = problem.y.size * problem.n_eff_factor
    return fit.chi2_total * problem.n_eff_factor + fit.n_params * math.log(n_eff)


def _simulation(recording: Recording, simulation, model: str | None, cortex_mm: float | None,
                bone_set: BoneSet):
    """The simulation on the recording's clock, the cortex [mm], a label and notes."""
    if simulation is None:
        require(model is not None, "give a simulation (a trace file) or a load model to diagnose against")
        sim, cortex, notes = inputs.model_simulation(recording, model, bone_set, cortex_mm)
        label = f"load model '{model}' (bone set '{bone_set.name}'), contact at {sim.contact_s:.3f} s"
        return sim, cortex, label, notes
    if isinstance(simulation, ModelSimulation):
        return simulation, float(cortex_mm or simulation.conditions.cortex_mm), f"load model '{simulation.model}'", []
    if isinstance(simulation, (str, os.PathLike)):
        sim = inputs.read_simulation(simulation, recording)
        label = os.path.basename(os.fspath(simulation))
    elif isinstance(simulation, Recording):
        sim = inputs.with_events(inputs.on_recording_clock(
            TraceSimulation.from_recording(simulation, recording.spindle_rpm), recording), recording)
        label = simulation.name
    else:
        sim = simulation if simulation.events is not None else inputs.with_events(simulation, recording)
        label = sim.label
    cortex, notes = inputs.trace_cortex(sim, recording, cortex_mm)
    return sim, cortex, label, notes


def _timing(problem: Problem, baseline: Fit, cortex_mm: float) -> Timing:
    sim = problem.simulation
    shift = baseline.params["shift_s"]
    events = getattr(sim, "events", None)
    if events is not None:
        on_clock = events.to_json(shift)
        source = "the simulation's breakthrough" if events.cortex_mm is not None else "depth reached"
        return Timing(on_clock["contact_s"], on_clock["feed_stop_s"], round(cortex_mm, 3),
                      TraceEventTimes(on_clock["full_engagement_s"], on_clock["breakthrough_s"],
                                      on_clock["depth_reached_mm"], source))
    return Timing(round(sim.contact_s + shift, 4), round(sim.stop_s + shift, 4) if math.isfinite(sim.stop_s) else None,
                  round(cortex_mm, 3))


def diagnose(recording, simulation=None, cortex_mm: float | None = None,
             bone: str | BoneSet = "bovine", progress=None, *, model: str | None = None,
             columns=None, overrides: dict | None = None, override_header: bool = False,
             bone_library: Path | None = None, workers: int = 1) -> Diagnosis:
    """Diagnose ``recording`` against a simulation (see the module docstring).

    Parameters
    ----------
    recording : a :class:`~femstudy.recordings.Recording`, or the path of a recording file
        (any format :func:`femstudy.recordings.read_recording` reads, with ``columns``,
        ``overrides`` and ``override_header`` passed to it).
    simulation : a simulated trace — a path in the recording format, a
        :class:`~femstudy.recordings.Recording`, or a :class:`.TraceSimulation` — or a
        :class:`.ModelSimulation`; None with ``model``.
    cortex_mm : cortical thickness [mm]; default: the recording's header ``cortex_mm``, else
        the simulation's breakthrough, else (no breakthrough) the depth reached, with a note.
    bone : bone set (or its name, resolved in ``bone_library``) giving μ_w for the friction
        reading of chip clogging without torque, and the friction of a load model.
    progress : optional callable taking one message per step (they also go to the logger).
    model : "allotta" or "clogging": diagnose against that femstudy load model instead, started
        at the recording's detected contact.
    workers : processes for the independent fits (:mod:`.workers`); the result is the same.

    Returns
    -------
    Diagnosis

    Examples
    --------
    >>> d = diagnose("rec.csv", "sim.csv")                           # doctest: +SKIP
    >>> d.to_json()["missing_physics"], d.to_json()["unexplained"]   # doctest: +SKIP
    """
    start = time.perf_counter()

    def say(message: str) -> None:
        logger.info(message)
        if progress:
            progress(message)

    if isinstance(recording, (str, os.PathLike)):
        recording = read_recording(recording, overrides, override_header=override_header, columns=columns)
        for note in recording.notes:
            say(note)
    bone_set = load_bone_set(bone, bone_library) if isinstance(bone, str) else bone
    sim, cortex, label, notes = _simulation(recording, simulation, model, cortex_mm, bone_set)
    say(f"read {recording.name} ({recording.time_s.size} samples) and the simulation ({label})")
    problem, more = build_problem(recording, sim, cortex)
    notes = notes + more
    baseline = align(problem)
    problem, noise_models, noise_notes = with_noise(problem, baseline, recording)
    notes += noise_notes
    baseline = restate(problem, baseline)
    say(f"{problem.band.t_dec.size} smoothed samples per channel ({', '.join(problem.channels)}); noise "
        + ", ".join(f"{c} alpha {m.exponent:.2f}, corner {m.corner_hz:.3g} Hz" for c, m in noise_models.items()))
    residual = problem.y - baseline.model
    mismatch = sorted((MismatchInterval(**interval) for c, name in enumerate(problem.channels)
                       for interval in mismatch_intervals(
                           problem.band.t_dec, residual[c] / problem.sigma[c], problem.n_eff_factor, name,
                           chi2_of=lambda lo, hi, c=c: openworld.interval_chi2(problem, c, residual[c], lo, hi))),
                      key=lambda i: (i.start_s, i.channel))
    say(f"aligned (shift {baseline.params['shift_s'] * 1e3:+.0f} ms); {len(mismatch)} mismatch interval(s)")
    with fitter(workers) as fits_of:
        start_params = {k: baseline.params[k] for k in problem.nonlinear_names(frozenset())}
        fits, selection = fit_and_select(problem, start_params, fits_of)
        say(f"fitted {len(fits)} mechanism subsets")
        if selection.residual_p_value <= RESIDUAL_P and any(scale_helps(problem, f, selection.inflation)
                                                            for f in (fits[selection.subset], baseline)):
            scaled = replace(problem, calibrate=True)
            scaled_fits, scaled_selection = fit_and_select(scaled, start_params, fits_of)
            if (plain_bic(scaled, scaled_fits[scaled_selection.subset])
                    < plain_bic(problem, fits[selection.subset]) - MIN_DELTA_BIC):
                problem, fits, selection = scaled, scaled_fits, scaled_selection
            say(f"refitted with the simulated loads rescaled: {'kept' if problem.calibrate else 'not better'}")
        verdict = decide(problem, fits, selection, baseline, fits_of)
        improved = verdict.fit
        span = openworld.cut_span(problem, improved.params)
        model_thrust = problem.predict(improved.params, recording.time_s)["thrust_N"]
        spindle = openworld.spindle_line(recording.time_s, recording.thrust_N, model_thrust, recording.spindle_rpm,
                                         (span[0] + problem.geometry.cone_mm / problem.geometry.feed_mm_s, span[1]))
        leftover = problem.y - improved.model
        for s in verdict.shapes:
            leftover = leftover - s.contribution()
        _, loads = openworld.modelled_loads(problem, improved.params)
        peaks = np.array([max(float(np.max(np.abs(L))), 1e-12) for L in loads])
        unexplained = openworld.report(problem, list(verdict.shapes), leftover, spindle, span, peaks)
        say(f"named {len(verdict.subset)} mechanism(s), {len(unexplained)} unexplained feature(s)")
        bone_mu_w = bone_set.friction(recording.feed_mm_s, recording.spindle_rpm)[1]
        mechanisms = explain.mechanisms(problem, improved, selection, verdict, bone_mu_w)
        summary = summarise_fit(problem, baseline, improved, fits_of)
    seconds = time.perf_counter() - start
    say(f"diagnosed in {seconds:.2f} s")
    return Diagnosis(recording, problem, baseline, fits, selection, verdict, tuple(mismatch), mechanisms, unexplained,
                     summary, noise_models, _timing(problem, baseline, cortex), label, seconds, tuple(notes))
