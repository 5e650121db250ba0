"""What a diagnosis found, typed: the record :func:`.diagnose.diagnose` returns and the report
reads (:mod:`.report`). Plain data and the JSON contract (:meth:`DiagnosisResult.to_json`,
docs/diagnosis.md); the printed summary and the files are :class:`.diagnose.Diagnosis`'s."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from femstudy.diagnosis.findings import ChannelFit, MismatchInterval, NamedMechanism, Timing, Unexplained
from femstudy.diagnosis.fit import Fit
from femstudy.diagnosis.mechanisms.problem import Problem
from femstudy.diagnosis.noise import NoiseSpectrum
from femstudy.diagnosis.select import Selection
from femstudy.diagnosis.verdict import Verdict
from femstudy.recordings.reader import Recording

UNITS = {"thrust_N": "N", "torque_Nmm": "N·mm"}


def alignment(problem: Problem, fit: Fit) -> dict:
    """The nuisance parameters of the aligned simulation (not physics)."""
    out = {"shift_s": round(fit.params["shift_s"], 4)}
    if "stop_depth_mm" in fit.params:
        out["stop_depth_mm"] = round(fit.params["stop_depth_mm"], 3)
    for c in problem.channels:
        out[f"{c}_tare"] = round(fit.params[f"{c}_tare"], 4)
    return out


def calibration(problem: Problem, fit: Fit) -> dict:
    """The scale on each channel's simulated cutting load in the improved fit (1 = as simulated)."""
    return {f"{c}_scale": round(fit.params.get(f"{c}_scale", 1.0), 4) for c in problem.channels}


@dataclass(frozen=True)
class DiagnosisResult:
    """What :func:`.diagnose.diagnose` found. Times are on the recording's clock [s], loads in N
    and N·mm.

    Attributes
    ----------
    recording : the recording diagnosed (:class:`~femstudy.recordings.Recording`).
    problem : the fitted problem: analysis band, channels, noise model, aligned simulation.
    baseline : the simulation as given, aligned (clock shift, tares): the "before" fit.
    fits : every fitted subset of the catalogue, by frozenset of mechanism names.
    selection : the model selection (BIC table, inclusion probabilities, what was dropped).
    verdict : the named subset, its fit, the shapes left unexplained, the confidences.
    mismatch : intervals where the aligned simulation departs from the recording beyond noise.
    mechanisms : the named mechanisms, most confident first.
    unexplained : what the best catalogue model leaves, characterised.
    fit_summary : per channel, R² (in sample and held out) and RMSE before and after.
    noise_models : per channel, the fitted :class:`~femstudy.diagnosis.noise.NoiseSpectrum`.
    timing : the simulation's events on the recording's clock, and the cortex [mm].
    simulation_label : what the recording was compared with.
    seconds : wall-clock time of the diagnosis [s].
    notes : how inputs were read or estimated (one sentence each).
    """

    recording: Recording
    problem: Problem
    baseline: Fit
    fits: dict[frozenset[str], Fit]
    selection: Selection
    verdict: Verdict
    mismatch: tuple[MismatchInterval, ...]
    mechanisms: tuple[NamedMechanism, ...]
    unexplained: tuple[Unexplained, ...]
    fit_summary: dict[str, ChannelFit]
    noise_models: dict[str, NoiseSpectrum]
    timing: Timing
    simulation_label: str
    seconds: float
    notes: tuple[str, ...] = ()

    @property
    def improved(self) -> Fit:
        return self.verdict.fit

    @property
    def subset(self) -> frozenset:
        """The named mechanisms."""
        return self.verdict.subset

    def to_json(self) -> dict:
        """The JSON contract, with per-channel, noise and selection detail added."""
        thrust = self.fit_summary["thrust_N"]
        return {
            "mismatch": [asdict(m) for m in self.mismatch],
            "missing_physics": [asdict(m) for m in self.mechanisms],
            "unexplained": [asdict(u) for u in self.unexplained],
            "fit": {"baseline": asdict(thrust.baseline), "improved": asdict(thrust.improved),
                    "window_s": list(thrust.window_s),
                    "channels": {c: {"baseline": asdict(s.baseline), "improved": asdict(s.improved)}
                                 for c, s in self.fit_summary.items()}},
            "alignment": alignment(self.problem, self.baseline),
            "calibration": calibration(self.problem, self.improved),
            "timing": self.timing.to_json(),
            "noise": {c: float(s) for c, s in zip(self.problem.channels, self.problem.sigma_raw)},
            "noise_model": {c: m.to_json(UNITS[c], self.problem.band.sigma_s) for c, m in self.noise_models.items()},
            "residual_check": {"chi2_per_dof": round(self.verdict.chi2_per_dof, 3),
                               "p_value": self.verdict.residual_p_value,
                               "consistent_with_noise": bool(self.verdict.consistent_with_noise)},
            "selection": {"bic": {"+".join(sorted(s)) or "none": round(b, 2)
                                  for s, b in sorted(self.selection.bic.items(), key=lambda kv: kv[1])},
                          "not_selected": {**self.selection.dropped, **self.verdict.dropped},
                          "inclusion_probability": {m: round(c, 4) for m, c in self.selection.confidence.items()}},
            "seconds": round(self.seconds, 3),
            "notes": list(self.notes),
        }
