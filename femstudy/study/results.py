"""Per-step response of one loading, and the numbers a paper needs from it.

Units: s, N, N·mm, mm, MPa.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from femstudy import thesis
from femstudy.femur_mesh import CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL, REGION_NAMES

_CANCELLOUS = {"ultimate": thesis.CANCELLOUS_STRENGTH_MPA["mean"], "source": "thesis Table 2-5, mean (range 0.56-22.9)"}
#: Strength per region [MPa] for the margin to failure: the lowest longitudinal cortical
#: limits (Table 2-4) and the mean cancellous strength (Table 2-5).
STRENGTH_MPA = {
    CORTICAL: {"yield": thesis.CORTICAL_STRENGTH_MPA["longitudinal_tension_yield"],
               "ultimate": thesis.CORTICAL_STRENGTH_MPA["longitudinal_tension_ultimate"],
               "source": "thesis Table 2-4, longitudinal tension"},
    CANCELLOUS_PROXIMAL: _CANCELLOUS, CANCELLOUS_DISTAL: _CANCELLOUS,
}

#: Study quantity → the response measure (femstudy.fe.outputs) it is read from.
MEASURES = {"max_deflection_mm": "deflection", "drill_point_deflection_mm": "drill_point",
            "max_von_mises_MPa": "von_mises", "max_von_mises_excl_MPa": "von_mises/outside"}


@dataclass(frozen=True)
class Peak:
    """The largest value of a quantity over the loading, when and where it occurs."""

    value: float
    time_s: float
    location_mm: tuple[float, float, float] | None = None

    def as_dict(self) -> dict:
        out = {"value": self.value, "time_s": self.time_s}
        if self.location_mm is not None:
            out["location_mm"] = [round(float(x), 3) for x in self.location_mm]
        return out


@dataclass(frozen=True, eq=False)
class LoadingResult:
    """The femur's response to one loading ("dynamic" or "static").

    time_s, thrust_N, torque_Nmm and ``series`` (quantity → values) are given at the recorded
    steps (every step of a short history); ``peaks`` are exact over every step.
    ``region_peaks`` maps a region name to its peak von Mises stress [MPa].
    """

    name: str
    time_s: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray
    series: dict[str, np.ndarray]
    peaks: dict[str, Peak]
    region_peaks: dict[str, float] = field(default_factory=dict)

    @classmethod
    def from_history(cls, name: str, all_times, thrust, torque, history) -> "LoadingResult":
        """From a :class:`femstudy.fe.outputs.History` of this loading over ``all_times``."""
        steps = history.recorded_steps
        t = np.asarray(all_times, float)
        series = {q: history[m].values for q, m in MEASURES.items()}
        peaks = {q: Peak(history[m].peak, float(t[history[m].peak_step]), tuple(history[m].peak_location))
                 for q, m in MEASURES.items()}
        regions = {REGION_NAMES[c]: history[f"von_mises/{REGION_NAMES[c]}"].peak for c in REGION_NAMES
                   if f"von_mises/{REGION_NAMES[c]}" in history.measures}
        return cls(name, t[steps], np.asarray(thrust, float)[steps], np.asarray(torque, float)[steps], series,
                   peaks, regions)

    def peak(self, quantity: str) -> Peak:
        return self.peaks[quantity]

    def margins(self) -> dict:
        """Strength / peak von Mises per region (Tables 2-4 and 2-5): the margin to failure."""
        out = {}
        codes = {name: code for code, name in REGION_NAMES.items()}
        for region, peak in self.region_peaks.items():
            limits = STRENGTH_MPA[codes[region]]
            entry = {"peak_von_mises_MPa": peak, "strength_source": limits["source"]}
            for kind in ("yield", "ultimate"):
                if kind in limits:
                    entry[f"{kind}_MPa"] = limits[kind]
                    entry[f"safety_factor_{kind}"] = (limits[kind] / peak) if peak > 0 else None
            out[region] = entry
        return out


TIMESERIES_COLUMNS = ["loading", "time_s", "thrust_N", "torque_Nmm", "max_deflection_mm",
                      "drill_point_deflection_mm", "max_von_mises_MPa", "max_von_mises_excl_MPa"]


def timeseries_rows(results: list[LoadingResult]) -> list[dict]:
    """Both loadings in long form: one dict per loading and recorded step, units in the keys."""
    rows = []
    for r in results:
        for k in range(len(r.time_s)):
            rows.append({"loading": r.name, "time_s": float(r.time_s[k]), "thrust_N": float(r.thrust_N[k]),
                         "torque_Nmm": float(r.torque_Nmm[k]),
                         **{q: float(r.series[q][k]) for q in MEASURES}})
    return rows


def timeseries_csv(results: list[LoadingResult]) -> str:
    """:func:`timeseries_rows` as CSV."""
    lines = [",".join(TIMESERIES_COLUMNS)]
    for row in timeseries_rows(results):
        lines.append(",".join([row["loading"]] + [f"{row[c]:.6g}" for c in TIMESERIES_COLUMNS[1:]]))
    return "\n".join(lines) + "\n"


def comparison(dynamic: LoadingResult, static: LoadingResult) -> dict:
    """Peaks of both loadings and their dynamic/static ratios."""
    out = {}
    for quantity in MEASURES:
        d, s = dynamic.peak(quantity), static.peak(quantity)
        out[quantity] = {"dynamic": d.as_dict(), "static": s.as_dict(),
                         "ratio_dynamic_to_static": d.value / s.value if s.value > 0 else None}
    return out
