"""Friction power law μ(f, N) and named bone coefficient sets (thesis Eqs 4.5–4.7).

    ln μ_f = a0 + a1 ln f + a2 ln N + a3 ln f ln N,
    ln μ_w = b0 + b1 ln f + b2 ln N + b3 ln f ln N,          (Eq 4.5)

with f in mm/s and N in rpm, fitted by linear least squares in ln μ over the calibration
conditions (Eqs 4.6–4.7: five conditions, four unknowns).

A *bone set* is a per-condition friction table plus the specific cutting energies of
cortical and cancellous bone; its power-law coefficients are always computed from the
table by :func:`fit_power_law`. The built-in sets "bovine" and "human" come from the
thesis's Tables 5-1 and 5-11 (package data). Calibrated sets are TOML files named
``<name>.toml`` in :func:`bone_library` (written by ``femstudy calibrate``).
"""

from __future__ import annotations

import csv
import json
import os
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from femstudy.errors import UserError, require

#: Cortical specific cutting energy u1 [MPa]: the Allotta full-engagement thrust
#: a sin(β/2) tan(β/2) u1 l equated to the mean initial force of Appendix B
#: (F_o = 25.686 N at f = 1.5 mm/s, N = 1500 rpm, a = 0.06 mm/rev, 2.7 mm 90° drill).
CORTICAL_SPECIFIC_ENERGY_MPA = 448.5
#: Cancellous specific cutting energy u2 [MPa]: u1 scaled by the ratio of cancellous
#: ultimate strength (Table 2-5 mean, 7.56 MPa) to cortical longitudinal tensile
#: strength (Table 2-4, 133 MPa). The thesis gives no value; see docs/load-models.md.
CANCELLOUS_SPECIFIC_ENERGY_MPA = round(CORTICAL_SPECIFIC_ENERGY_MPA * 7.56 / 133, 1)

BUILTIN_TABLES = {
    "bovine": ("table_5_1_bovine_friction.csv", "thesis Table 5-1, bovine femur"),
    "human": ("table_5_11_human_friction.csv", "thesis Table 5-11, human femur"),
}


def _design(feed_mm_s, spindle_rpm) -> np.ndarray:
    lf, ln = np.log(np.asarray(feed_mm_s, float)), np.log(np.asarray(spindle_rpm, float))
    return np.column_stack([np.ones_like(lf), lf, ln, lf * ln])


def fit_power_law(feed_mm_s, spindle_rpm, mu) -> np.ndarray:
    """Least-squares coefficients (c0, c1, c2, c3) of ln μ = c0 + c1 ln f + c2 ln N + c3 ln f ln N."""
    mu = np.asarray(mu, float)
    require(mu.size >= 4, f"the power law has 4 coefficients and needs at least 4 "
                          f"calibration conditions, got {mu.size}")
    require(bool(np.all(mu > 0)), "friction coefficients must be positive to fit ln μ")
    A = _design(feed_mm_s, spindle_rpm)
    require(np.linalg.matrix_rank(A) == 4,
            "the calibration conditions do not determine the power law: use at least two "
            "feeds and two spindle speeds, not all on one line in (ln f, ln N)")
    coef, *_ = np.linalg.lstsq(A, np.log(mu), rcond=None)
    return coef


def evaluate_power_law(coef, feed_mm_s, spindle_rpm):
    """μ(f, N) = exp(c0 + c1 ln f + c2 ln N + c3 ln f ln N)."""
    A = _design(np.atleast_1d(feed_mm_s), np.atleast_1d(spindle_rpm))
    out = np.exp(A @ np.asarray(coef, float))
    return out if np.ndim(feed_mm_s) or np.ndim(spindle_rpm) else float(out[0])


@dataclass(frozen=True)
class BoneSet:
    """Friction calibration of one drill-and-bone combination."""

    name: str
    feed_mm_s: tuple[float, ...]
    spindle_rpm: tuple[float, ...]
    mu_f: tuple[float, ...]
    mu_w: tuple[float, ...]
    u1_MPa: float = CORTICAL_SPECIFIC_ENERGY_MPA
    u2_MPa: float = CANCELLOUS_SPECIFIC_ENERGY_MPA
    source: str = ""
    a: np.ndarray = field(init=False, repr=False, compare=False)
    b: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        require(self.u1_MPa > 0 and self.u2_MPa >= 0,
                f"bone set '{self.name}': specific cutting energies must be u1 > 0, u2 >= 0")
        object.__setattr__(self, "a", fit_power_law(self.feed_mm_s, self.spindle_rpm, self.mu_f))
        object.__setattr__(self, "b", fit_power_law(self.feed_mm_s, self.spindle_rpm, self.mu_w))

    def friction(self, feed_mm_s: float, spindle_rpm: float) -> tuple[float, float]:
        """(μ_f, μ_w) from the power law at feed f [mm/s] and speed N [rpm]."""
        return (evaluate_power_law(self.a, feed_mm_s, spindle_rpm),
                evaluate_power_law(self.b, feed_mm_s, spindle_rpm))

    def in_calibrated_range(self, feed_mm_s: float, spindle_rpm: float) -> bool:
        """True when (f, N) lies inside the box spanned by the calibration conditions."""
        return (min(self.feed_mm_s) <= feed_mm_s <= max(self.feed_mm_s)
                and min(self.spindle_rpm) <= spindle_rpm <= max(self.spindle_rpm))

    def to_toml(self) -> str:
        """The set as a TOML document that :func:`load_bone_set` reads back."""
        lines = [f"name = {json.dumps(self.name)}", f"source = {json.dumps(self.source)}",
                 f"u1_MPa = {self.u1_MPa!r}", f"u2_MPa = {self.u2_MPa!r}",
                 "# power-law coefficients, recomputed from the conditions when loaded",
                 f"a = {[round(float(x), 6) for x in self.a]}",
                 f"b = {[round(float(x), 6) for x in self.b]}", ""]
        for f, n, mf, mw in zip(self.feed_mm_s, self.spindle_rpm, self.mu_f, self.mu_w):
            lines += ["[[condition]]", f"feed_mm_s = {f!r}", f"spindle_rpm = {n!r}",
                      f"mu_f = {mf!r}", f"mu_w = {mw!r}", ""]
        return "\n".join(lines)


def _read_table(filename: str) -> list[dict]:
    text = resources.files("femstudy.drilling").joinpath("data", filename).read_text()
    rows = [line for line in text.splitlines() if line and not line.startswith("#")]
    return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(rows)]


def builtin_bone_set(name: str) -> BoneSet:
    """The thesis's bovine (Table 5-1) or human (Table 5-11) set."""
    filename, source = BUILTIN_TABLES[name]
    rows = _read_table(filename)
    return BoneSet(name=name, source=source,
                   **{k: tuple(r[k] for r in rows)
                      for k in ("feed_mm_s", "spindle_rpm", "mu_f", "mu_w")})


def bone_library() -> Path:
    """Folder of calibrated sets: $FEMSTUDY_BONES, else $XDG_DATA_HOME/femstudy/bones."""
    if "FEMSTUDY_BONES" in os.environ:
        return Path(os.environ["FEMSTUDY_BONES"])
    data_home = os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share"
    return Path(data_home) / "femstudy" / "bones"


def read_bone_set_file(path: Path) -> BoneSet:
    """Read a bone-set TOML file written by :meth:`BoneSet.to_toml`."""
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise UserError(f"cannot read bone set {path}: {exc}") from None
    try:
        conditions = doc["condition"]
        return BoneSet(name=str(doc.get("name", path.stem)), source=str(doc.get("source", path)),
                       u1_MPa=float(doc.get("u1_MPa", CORTICAL_SPECIFIC_ENERGY_MPA)),
                       u2_MPa=float(doc.get("u2_MPa", CANCELLOUS_SPECIFIC_ENERGY_MPA)),
                       **{k: tuple(float(c[k]) for c in conditions)
                          for k in ("feed_mm_s", "spindle_rpm", "mu_f", "mu_w")})
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"bone set {path} is missing or has a bad entry: {exc}") from None


def load_bone_set(name: str) -> BoneSet:
    """Resolve a bone-set name: built-in, a path to a .toml file, or a calibrated set."""
    if name in BUILTIN_TABLES:
        return builtin_bone_set(name)
    path = Path(name)
    if path.suffix == ".toml" and path.is_file():
        return read_bone_set_file(path)
    library = bone_library()
    candidate = library / f"{name}.toml"
    if candidate.is_file():
        return read_bone_set_file(candidate)
    calibrated = sorted(p.stem for p in library.glob("*.toml")) if library.is_dir() else []
    known = ", ".join(list(BUILTIN_TABLES) + calibrated)
    raise UserError(f"unknown bone coefficient set '{name}': choose one of {known}, "
                    f"or a calibrated set (femstudy calibrate --name {name})")

