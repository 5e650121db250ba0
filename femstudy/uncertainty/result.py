"""What an uncertainty run produced, typed: :class:`UncertaintyResult` and its per-femur parts.

Statistics of an output: mean, SD and the 5/50/95 % quantiles over its samples (NaN-free ones);
the probability that the governing margin falls below 1 is the fraction of hole samples below
1 with its Wilson 95 % interval. Units in the names: mm, N, N·mm, MPa.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: The outputs whose distributions are summarised (and analysed, with the sobol method).
OUTPUTS = ("max_deflection_mm", "drill_point_deflection_mm", "hole_von_mises_MPa", "hole_exclusion_von_mises_MPa",
           "governing_margin")
#: The outputs every sample has (the Sobol indices need every evaluation).
GLOBAL_OUTPUTS = ("max_deflection_mm", "drill_point_deflection_mm")


def statistics(values) -> dict | None:
    """mean, sd, p5, p50, p95 and n of the finite values (None if there are none)."""
    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return None
    p5, p50, p95 = np.percentile(x, [5, 50, 95])
    return {"mean": float(x.mean()), "sd": float(x.std(ddof=1)) if x.size > 1 else 0.0, "p5": float(p5),
            "p50": float(p50), "p95": float(p95), "n": int(x.size)}


def probability_below(values, threshold: float = 1.0) -> dict | None:
    """P(value < threshold) over the finite values, with its Wilson 95 % interval."""
    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return None
    n, k, z = x.size, int(np.sum(x < threshold)), 1.959963984540054
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return {"probability": p, "below": k, "n": n, "wilson95": [max(0.0, centre - half), min(1.0, centre + half)]}


@dataclass(frozen=True)
class FemurUncertainty:
    """One case's samples and their summary.

    name : the case's name; surface : its femur; inputs : input name → distribution (dict)
    unit : (n, D) design in the unit cube; samples : column → (n,) array (inputs and outputs)
    nominal : outputs at the nominal inputs; sensitivity : output → indices (sobol) or rank
    correlations (montecarlo); reduced : the reduced basis's snapshots, λ₀ and largest bound
    """

    name: str
    surface: str
    inputs: dict[str, dict[str, Any]]
    unit: np.ndarray
    samples: dict[str, np.ndarray]
    nominal: dict[str, Any]
    sensitivity: dict[str, dict[str, Any]]
    reduced: dict | None
    margin_basis: str | None
    seconds: dict[str, float]

    def summary(self) -> dict:
        out = {o: statistics(self.samples[o]) for o in OUTPUTS if o in self.samples}
        out["P(governing_margin < 1)"] = probability_below(self.samples.get("governing_margin", []))
        return out


@dataclass(frozen=True)
class UncertaintyResult:
    """The outcome of :func:`femstudy.uncertainty.run.run_uncertainty`: per femur and pooled.

    method : "montecarlo" or "sobol"; samples : base samples asked for; evaluations : per femur
    femurs : one :class:`FemurUncertainty` per case; out_dir : the results folder
    execution : how it ran (workers, scheduler, memory limit per worker, peak memory seen)
    """

    method: str
    samples: int
    femurs: tuple
    execution: dict[str, Any]
    out_dir: Path | None = None
    files: tuple = field(default_factory=tuple)

    def pooled(self) -> dict:
        """The outputs' statistics over every femur's samples together."""
        joined = {o: np.concatenate([f.samples[o] for f in self.femurs]) for o in OUTPUTS}
        out = {o: statistics(v) for o, v in joined.items()}
        out["P(governing_margin < 1)"] = probability_below(joined["governing_margin"])
        return out

    def rows(self) -> list[dict]:
        """Every sample as a flat dict (case, sample index, inputs, outputs), for CSV."""
        rows = []
        for f in self.femurs:
            columns = list(f.samples)
            for i in range(len(f.unit)):
                rows.append({"case": f.name, "sample": i, **{c: f.samples[c][i] for c in columns}})
        return rows

    def to_json(self) -> dict:
        from femstudy import __version__
        from femstudy.jsonable import jsonable

        return jsonable({
            "femstudy_version": __version__, "method": self.method, "samples": self.samples,
            "execution": self.execution,
            "femurs": [{"case": f.name, "surface": f.surface, "inputs": f.inputs, "evaluations": len(f.unit),
                        "nominal": f.nominal, "summary": f.summary(), "sensitivity": f.sensitivity,
                        "reduced_basis": f.reduced, "margin_basis": f.margin_basis, "seconds": f.seconds}
                       for f in self.femurs],
            "pooled": self.pooled() if len(self.femurs) > 1 else None,
        })
