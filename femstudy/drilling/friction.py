"""Friction power law μ(f, N) and named bone coefficient sets (thesis Eqs 4.5–4.7).

    ln μ_f = a0 + a1 ln f + a2 ln N + a3 ln f ln N,
    ln μ_w = b0 + b1 ln f + b2 ln N + b3 ln f ln N,          (Eq 4.5)

with f in mm/s and N in rpm, fitted by linear least squares in ln μ over the calibration
conditions (Eqs 4.6–4.7: five conditions, four unknowns).

A *bone set* is a per-condition friction table plus the specific cutting energies of
cortical and cancellous bone; its power-law coefficients are always computed from the
table by :func:`fit_power_law`. The built-in sets "bovine" and "human" come from the
thesis's Tables 5-1 and 5-11 (package data). Calibrated sets are TOML files named
``<name>.toml`` in a bone library folder (written by ``femstudy calibrate``;
:func:`default_bone_library` unless one is given).
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from femstudy import thesis
from femstudy.errors import UserError, require
from femstudy.schema import parse_toml

#: Specific cutting energies u1 (cortical) and u2 (cancellous) [MPa]: derived values, the
#: thesis gives none (femstudy.thesis, docs/load-models.md).
CORTICAL_SPECIFIC_ENERGY_MPA = thesis.CORTICAL_SPECIFIC_ENERGY_MPA
CANCELLOUS_SPECIFIC_ENERGY_MPA = thesis.CANCELLOUS_SPECIFIC_ENERGY_MPA

BUILTIN_TABLES = {
    "bovine": ("table_5_1_bovine_friction.csv", "thesis Table 5-1, bovine femur"),
    "human": ("table_5_11_human_friction.csv", "thesis Table 5-11, human femur"),
    "human-printed": ("table_5_12_human_printed.csv", "thesis Table 5-12 / Eqs 5.8-5.9 as printed, human femur"),
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


def default_bone_library() -> Path:
    """The user's folder of calibrated sets: femstudy/bones in the platform's user data folder
    (``~/.local/share/femstudy/bones`` on Linux, following ``$XDG_DATA_HOME``)."""
    import platformdirs

    return platformdirs.user_data_path("femstudy") / "bones"


class ConditionRow(BaseModel):
    """One calibrated condition of a bone-set file: feed [mm/s], speed [rpm], μ_f, μ_w."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    feed_mm_s: float = Field(gt=0, allow_inf_nan=False)
    spindle_rpm: float = Field(gt=0, allow_inf_nan=False)
    mu_f: float = Field(gt=0, allow_inf_nan=False)
    mu_w: float = Field(gt=0, allow_inf_nan=False)


class BoneSetFile(BaseModel):
    """A bone-set TOML file as :meth:`BoneSet.to_toml` writes it; ``a`` and ``b`` (the power
    law) are informative and recomputed from the conditions."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str | None = None
    source: str | None = None
    u1_MPa: float = Field(CORTICAL_SPECIFIC_ENERGY_MPA, gt=0, allow_inf_nan=False)
    u2_MPa: float = Field(CANCELLOUS_SPECIFIC_ENERGY_MPA, ge=0, allow_inf_nan=False)
    a: list[float] = []
    b: list[float] = []
    condition: list[ConditionRow] = Field(min_length=4)


def read_bone_set_file(path: Path) -> BoneSet:
    """Read a bone-set TOML file written by :meth:`BoneSet.to_toml` (schema :class:`BoneSetFile`)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read bone set {path}: {exc}") from None
    doc = parse_toml(text, BoneSetFile, f"bone set {path}")
    return BoneSet(name=doc.name or Path(path).stem, source=doc.source or str(path), u1_MPa=doc.u1_MPa,
                   u2_MPa=doc.u2_MPa, **{k: tuple(getattr(c, k) for c in doc.condition)
                                         for k in ("feed_mm_s", "spindle_rpm", "mu_f", "mu_w")})


def load_bone_set(name: str, library: Path | None = None) -> BoneSet:
    """Resolve a bone-set name: built-in, a path to a .toml file, or a calibrated set in
    ``library`` (default :func:`default_bone_library`)."""
    if name in BUILTIN_TABLES:
        return builtin_bone_set(name)
    path = Path(name)
    if path.suffix == ".toml" and path.is_file():
        return read_bone_set_file(path)
    library = default_bone_library() if library is None else Path(library)
    candidate = library / f"{name}.toml"
    if candidate.is_file():
        return read_bone_set_file(candidate)
    calibrated = sorted(p.stem for p in library.glob("*.toml")) if library.is_dir() else []
    known = ", ".join(list(BUILTIN_TABLES) + calibrated)
    raise UserError(f"unknown bone coefficient set '{name}': choose one of {known}, "
                    f"or a calibrated set (femstudy calibrate --name {name})")
