"""The parts of a diagnosis's findings, typed: mismatch intervals, named mechanisms, what is left
unexplained, the fit scores and the timing (gathered in :class:`.result.DiagnosisResult`; its
``to_json`` turns them into the contract's dicts)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MismatchInterval:
    """Where the aligned simulation departs from the recording beyond noise (:mod:`.locate`)."""

    start_s: float
    end_s: float
    channel: str
    significance: float          # −log10 p of the interval's χ² test
    max_abs_z: float


@dataclass(frozen=True)
class Evidence:
    """Why a mechanism is named: drop-one ΔBIC, its size, its posterior inclusion probability."""

    delta_bic: float
    size: float
    inclusion_probability: float


@dataclass(frozen=True)
class NamedMechanism:
    """A named missing mechanism: confidence, physical parameters, explanation, evidence."""

    mechanism: str
    confidence: float
    parameters: dict[str, float | str]
    explanation: str
    evidence: Evidence


@dataclass(frozen=True)
class Unexplained:
    """What the best catalogue model leaves, characterised (:mod:`.openworld`); ``evidence``
    holds the shape's gain, size and parameters, the spindle line, or the significance."""

    start_s: float
    end_s: float
    channel: str                 # "thrust_N", "torque_Nmm" or "both"
    kind: str
    description: str
    evidence: dict[str, float]


@dataclass(frozen=True)
class Scores:
    """R² in sample and held out, and RMSE, of a fit over the cut."""

    r2: float
    r2_heldout: float
    rmse: float


@dataclass(frozen=True)
class ChannelFit:
    """One channel's fit before (the aligned simulation) and after (with the named mechanisms)."""

    baseline: Scores
    improved: Scores
    window_s: tuple[float, float]


@dataclass(frozen=True)
class TraceEventTimes:
    """A simulated trace's detected events on the recording's clock [s] (None where it has none)."""

    full_engagement_s: float | None
    breakthrough_s: float | None
    depth_reached_mm: float
    cortex_source: str           # "the simulation's breakthrough" or "depth reached"


@dataclass(frozen=True)
class Timing:
    """The simulation's events on the recording's clock [s] and the cortex [mm]; ``trace`` a
    simulated trace's detected events (None for a load model)."""

    contact_s: float | None
    feed_stop_s: float | None
    cortex_mm: float
    trace: TraceEventTimes | None = None

    def to_json(self) -> dict:
        if self.trace is None:
            return {"contact_s": self.contact_s, "feed_stop_s": self.feed_stop_s, "cortex_mm": self.cortex_mm}
        return {"contact_s": self.contact_s, "full_engagement_s": self.trace.full_engagement_s,
                "breakthrough_s": self.trace.breakthrough_s, "feed_stop_s": self.feed_stop_s,
                "cortex_mm": self.cortex_mm, "depth_reached_mm": self.trace.depth_reached_mm,
                "cortex_source": self.trace.cortex_source}
