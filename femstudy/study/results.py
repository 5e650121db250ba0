"""Per-step response of one loading, and the numbers a paper needs from it.

Units: s, N, N·mm, mm, MPa, mJ (= N·mm).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from femstudy.femur_model import REGION_NAMES
from femstudy.study.thesis import STRENGTH_MPA


@dataclass(frozen=True)
class LoadingResult:
    """Response of the femur to one loading ("dynamic" or "static"), one entry per time step.

    Point arrays are (n_steps, 3) [mm]: where the maximum occurs at that step.
    ``region_max_von_mises_MPa`` maps a region code to its per-step maximum.
    """

    name: str
    time_s: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray
    max_deflection_mm: np.ndarray
    max_deflection_point: np.ndarray
    drill_point_deflection_mm: np.ndarray
    max_von_mises_MPa: np.ndarray
    max_von_mises_point: np.ndarray
    max_von_mises_excl_MPa: np.ndarray
    max_von_mises_excl_point: np.ndarray
    region_max_von_mises_MPa: dict = field(default_factory=dict)
    strain_energy_mJ: np.ndarray | None = None

    def peak(self, quantity: str) -> dict:
        """The maximum over time of a per-step quantity, with its time and location."""
        values = getattr(self, quantity)
        k = int(np.argmax(values))
        out = {"value": float(values[k]), "time_s": float(self.time_s[k])}
        point_name = {"max_deflection_mm": "max_deflection_point",
                      "max_von_mises_MPa": "max_von_mises_point",
                      "max_von_mises_excl_MPa": "max_von_mises_excl_point"}.get(quantity)
        if point_name:
            out["location_mm"] = [round(float(x), 3) for x in getattr(self, point_name)[k]]
        return out

    def margins(self) -> dict:
        """Strength / peak von Mises per region (Tables 2-4 and 2-5): the margin to failure."""
        out = {}
        for code, series in self.region_max_von_mises_MPa.items():
            peak = float(np.max(series))
            limits = STRENGTH_MPA[code]
            entry = {"peak_von_mises_MPa": peak, "strength_source": limits["source"]}
            for kind in ("yield", "ultimate"):
                if kind in limits:
                    entry[f"{kind}_MPa"] = limits[kind]
                    entry[f"safety_factor_{kind}"] = (limits[kind] / peak) if peak > 0 else None
            out[REGION_NAMES[code]] = entry
        return out


TIMESERIES_COLUMNS = ["loading", "time_s", "thrust_N", "torque_Nmm", "max_deflection_mm",
                      "drill_point_deflection_mm", "max_von_mises_MPa", "max_von_mises_excl_MPa"]


def timeseries_csv(results: list[LoadingResult]) -> str:
    """Both loadings in long form, one row per loading and step, units in the column names."""
    lines = [",".join(TIMESERIES_COLUMNS)]
    for r in results:
        for k in range(len(r.time_s)):
            values = [r.time_s[k], r.thrust_N[k], r.torque_Nmm[k], r.max_deflection_mm[k],
                      r.drill_point_deflection_mm[k], r.max_von_mises_MPa[k], r.max_von_mises_excl_MPa[k]]
            lines.append(",".join([r.name] + [f"{v:.6g}" for v in values]))
    return "\n".join(lines) + "\n"


def comparison(dynamic: LoadingResult, static: LoadingResult) -> dict:
    """Peaks of both loadings and their dynamic/static ratios."""
    out = {}
    for quantity in ("max_deflection_mm", "drill_point_deflection_mm",
                     "max_von_mises_MPa", "max_von_mises_excl_MPa"):
        d, s = dynamic.peak(quantity), static.peak(quantity)
        out[quantity] = {"dynamic": d, "static": s,
                         "ratio_dynamic_to_static": d["value"] / s["value"] if s["value"] > 0 else None}
    return out
