"""The typed result of a diagnosis: :class:`Diagnosis` and its records. Dicts exist only in ``to_json()``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from femstudy.diagnosis.catalogue import Check, Reading
from femstudy.diagnosis.confidence import Evidence, confidence
from femstudy.diagnosis.fit import Fit
from femstudy.diagnosis.noise import NoiseSpectrum
from femstudy.diagnosis.outside import Unexplained
from femstudy.diagnosis.problem import Problem
from femstudy.diagnosis.select import RESIDUAL_P, Selection
from femstudy.diagnosis.verdict import Verdict
from femstudy.recordings.reader import Recording

UNITS = {"thrust_N": "N", "torque_Nmm": "N·mm"}


@dataclass(frozen=True)
class Mismatch:
    """An interval where the aligned simulation departs from the recording beyond noise."""

    start_s: float
    end_s: float
    channel: str
    significance: float          #: −log10 p of the interval's χ² test
    max_abs_z: float

    def to_json(self) -> dict:
        return {"start_s": round(self.start_s, 3), "end_s": round(self.end_s, 3), "channel": self.channel,
                "significance": self.significance, "max_abs_z": self.max_abs_z}


@dataclass(frozen=True)
class Named:
    """A named mechanism: its confidence, physical reading and the evidence."""

    mechanism: str
    confidence: float
    reading: Reading
    size: float
    inclusion_probability: float
    checks: tuple[Check, ...]
    evidence: Evidence

    def to_json(self) -> dict:
        return {"mechanism": self.mechanism, "confidence": round(self.confidence, 4),
                "parameters": {p.name: p.value for p in self.reading.parameters},
                "explanation": self.reading.text,
                "evidence": {**self.evidence.to_json(), "size": float(f"{self.size:.4g}"),
                             "inclusion_probability": round(self.inclusion_probability, 4),
                             "signatures": {c.name: {"passed": bool(c.passed), "value": float(f"{c.value:.4g}")}
                                            for c in self.checks}}}


@dataclass(frozen=True)
class Scores:
    """R² in sample and held out, and RMSE, of the smoothed recording over the cut."""

    r2: float
    r2_heldout: float
    rmse: float

    def to_json(self) -> dict:
        return {"r2": self.r2, "r2_heldout": self.r2_heldout, "rmse": self.rmse}


@dataclass(frozen=True)
class ChannelFit:
    """One channel's fit before (the simulation aligned) and after (with the named mechanisms)."""

    channel: str
    baseline: Scores
    improved: Scores
    window_s: tuple[float, float]


@dataclass(frozen=True)
class Timing:
    """The simulation's events on the recording's clock [s] and the cortex used [mm]."""

    contact_s: float | None
    full_engagement_s: float | None = None
    breakthrough_s: float | None = None
    feed_stop_s: float | None = None
    cortex_mm: float = math.nan
    depth_reached_mm: float | None = None
    cortex_source: str = ""

    def to_json(self) -> dict:
        return {"contact_s": self.contact_s, "full_engagement_s": self.full_engagement_s,
                "breakthrough_s": self.breakthrough_s, "feed_stop_s": self.feed_stop_s,
                "cortex_mm": round(self.cortex_mm, 3), "depth_reached_mm": self.depth_reached_mm,
                "cortex_source": self.cortex_source}


@dataclass(frozen=True)
class ResidualCheck:
    """The χ² test of the final model's residual under the noise model."""

    chi2_per_dof: float
    p_value: float

    @property
    def consistent_with_noise(self) -> bool:
        return self.p_value > RESIDUAL_P

    def to_json(self) -> dict:
        return {"chi2_per_dof": round(self.chi2_per_dof, 3), "p_value": self.p_value,
                "consistent_with_noise": bool(self.consistent_with_noise)}


@dataclass(frozen=True)
class ChannelNoise:
    """A channel's fitted noise spectrum."""

    channel: str
    spectrum: NoiseSpectrum


@dataclass(frozen=True)
class Diagnosis:
    """The result of :func:`~femstudy.diagnosis.diagnose`: everything ``femstudy diagnose`` reports.

    :meth:`to_json` is the JSON contract (docs/diagnosis.md), :meth:`summary` the printed text and
    :meth:`write` the files. Times are on the recording's clock [s], loads in N and N·mm.

    Attributes
    ----------
    recording : the recording diagnosed (after the channel corrections of :mod:`.sanity`).
    problem : the fitted problem: analysis band, channels, noise model, aligned simulation.
    baseline : the simulation as given, aligned (clock shift, tares): the "before" fit.
    fits : the best fit of every subset of the catalogue.
    selection : the model selection (BIC table, inclusion probabilities, tests, what was dropped).
    verdict : the named subset, its fit, the shapes left unexplained, what shapes replaced.
    mismatch : where the aligned simulation departs from the recording beyond noise.
    mechanisms : the named mechanisms.
    unexplained : channel findings, events in air and what the best catalogue model leaves.
    fit_summary : per channel, R² (in sample and held out) and RMSE before and after.
    noise_models : per channel, the fitted noise spectrum.
    timing : the simulation's events on the recording's clock, and the cortex.
    residual_check : the χ² test of the final residual against the noise model.
    simulation_label : what the recording was compared with.
    seconds : wall-clock time of the diagnosis [s].
    notes : how inputs were read or estimated (one sentence each).
    """

    recording: Recording
    problem: Problem
    baseline: Fit
    fits: tuple[Fit, ...]
    selection: Selection
    verdict: Verdict
    mismatch: tuple[Mismatch, ...]
    mechanisms: tuple[Named, ...]
    unexplained: tuple[Unexplained, ...]
    fit_summary: tuple[ChannelFit, ...]
    noise_models: tuple[ChannelNoise, ...]
    timing: Timing
    residual_check: ResidualCheck
    simulation_label: str
    seconds: float
    notes: tuple[str, ...] = ()

    @property
    def improved(self) -> Fit:
        return self.verdict.fit

    @property
    def subset(self) -> frozenset:
        """The named mechanisms."""
        return frozenset(m.mechanism for m in self.mechanisms)

    def summary(self) -> str:
        """The printed summary (:func:`.report.summary_text`)."""
        from femstudy.diagnosis import report

        return report.summary_text(self)

    def write(self, json_path=None, plot_path=None, report_dir=None) -> list[Path]:
        """Write the JSON contract, the overlay/residual figure and the report folder (report.md,
        overlay.png, residuals.png, diagnosis.json), each atomically; returns what was written.

        Examples
        --------
        >>> d.write(json_path="d.json", report_dir="report")  # doctest: +SKIP
        [PosixPath('d.json'), PosixPath('report/report.md')]
        """
        from femstudy.diagnosis import report

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

    def to_json(self) -> dict:
        """The JSON contract {"mismatch", "missing_physics", "unexplained", "fit"}, with the alignment,
        calibration, timing, noise and selection detail."""
        problem, improved = self.problem, self.improved
        thrust = next(c for c in self.fit_summary if c.channel == "thrust_N")
        selection = self.selection
        return {
            "mismatch": [m.to_json() for m in self.mismatch],
            "missing_physics": [m.to_json() for m in self.mechanisms],
            "unexplained": [u.to_json() for u in self.unexplained],
            "fit": {"baseline": thrust.baseline.to_json(), "improved": thrust.improved.to_json(),
                    "window_s": list(thrust.window_s),
                    "channels": {c.channel: {"baseline": c.baseline.to_json(), "improved": c.improved.to_json()}
                                 for c in self.fit_summary}},
            "alignment": {"shift_s": round(problem.shift_s + self.baseline.value("shift_correction_s"), 4),
                          **({"stop_depth_mm": round((problem.stop_depth_mm or 0.0)
                                                     + self.baseline.value("stop_correction_mm", 0.0), 3)}
                             if problem.stop_depth_mm is not None else {}),
                          **{f"{c}_tare": round(self.baseline.value(f"{c}_tare"), 4) for c in problem.channels}},
            "calibration": {f"{c}_scale": round(improved.value(f"{c}_scale", 1.0), 4) for c in problem.channels},
            "timing": self.timing.to_json(),
            "noise": {c: float(s) for c, s in zip(problem.channels, problem.sigma_raw)},
            "noise_model": {n.channel: n.spectrum.to_json(UNITS[n.channel], problem.band.sigma_s)
                            for n in self.noise_models},
            "residual_check": self.residual_check.to_json(),
            "selection": {"bic": {"+".join(sorted(s)) or "none": round(b, 2)
                                  for s, b in sorted(selection.bic.items(), key=lambda kv: kv[1])},
                          "not_selected": {d.mechanism: d.reason for d in selection.dropped + self.verdict.replaced},
                          "dropped_by_confidence": {d.mechanism: {"confidence": round(confidence(d.evidence), 4),
                                                                  "evidence": d.evidence.to_json()}
                                                    for d in self.verdict.replaced if d.evidence is not None},
                          "inclusion_probability": {m: round(c, 4) for m, c in selection.inclusion.items()}},
            "seconds": round(self.seconds, 3),
            "notes": list(self.notes),
        }
