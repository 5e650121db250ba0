"""Case files: TOML checked against a schema, with errors that name the key and the line.

Every section has defaults that reproduce the thesis's FE set-up (§3.3, §5.9). Units are
in the key names; material properties are given in the units the thesis tables use (GPa,
kg/m³) and converted to the solver's MPa and tonne/mm³ by :class:`MaterialSpec`.
"""

from __future__ import annotations

import difflib
import re
import tomllib
from pathlib import Path
from typing import Annotated, Literal, Union

from pydantic import (BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, field_validator,
                      model_validator)

from femstudy.errors import UserError

PositiveMM = Annotated[float, Field(gt=0, allow_inf_nan=False)]


def _three_numbers(value):
    ok = (isinstance(value, (list, tuple)) and len(value) == 3
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
          and any(v != 0 for v in value))
    if not ok:
        raise ValueError("a non-zero vector of three numbers [x, y, z]")
    return tuple(float(v) for v in value)


Vector3 = Annotated[tuple[float, float, float], BeforeValidator(_three_numbers)]
ANATOMICAL_DIRECTIONS = ("anterior", "posterior", "lateral", "medial")


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class CortexSpec(_Section):
    """Cortical shell thickness along the long axis [mm]."""

    midshaft_mm: PositiveMM = 6.0
    epiphysis_mm: PositiveMM = 2.0


class CanalSpec(_Section):
    """Empty medullary canal: diameter at mid-shaft and its extent as fractions of length
    measured from the proximal end (0 = top of the head, 1 = bottom of the condyles).

    Cancellous bone between the canal and the cortex thinner than ``min_cancellous_mm`` is
    not kept: the canal then reaches the cortex (docs/meshing.md)."""

    diameter_mm: PositiveMM = 13.0
    min_cancellous_mm: float = Field(3.0, ge=0, le=20)
    proximal_fraction: float = Field(0.22, gt=0, lt=1)
    distal_fraction: float = Field(0.78, gt=0, lt=1)

    @model_validator(mode="after")
    def _ordered(self):
        if self.proximal_fraction >= self.distal_fraction:
            raise ValueError("proximal_fraction must be smaller than distal_fraction")
        return self


class GeometrySpec(_Section):
    """The bone surface and how to read it. ``bodies``: a file holding several separate
    bodies (a femur exported with its patella, loose fragments) is refused with their sizes
    (``"one"``) or meshed by its largest body (``"largest"``)."""

    surface: str = "builtin"
    bodies: Literal["one", "largest"] = "one"
    units: Literal["auto", "mm", "cm", "m", "in"] = "auto"
    long_axis: Union[Literal["auto"], Vector3] = "auto"
    anterior: Union[Literal["auto"], Vector3] = "auto"
    proximal_end: Literal["auto", "+", "-"] = "auto"
    side: Literal["auto", "left", "right"] = "auto"
    cortex: CortexSpec = CortexSpec()
    canal: CanalSpec = CanalSpec()


class MeshSpec(_Section):
    """TetWild target edge lengths [mm] and element order."""

    size_mm: PositiveMM = 8.0
    refine: Literal["site", "uniform"] = "site"
    site_size_mm: PositiveMM = 1.0
    site_radius_mm: PositiveMM = 12.0
    envelope: float = Field(1e-3, gt=0, le=0.05)
    order: Literal[1, 2] = 2


class MaterialSpec(_Section):
    """Isotropic linear elastic material in the thesis's units (Table 3-1)."""

    youngs_modulus_GPa: float = Field(gt=0, le=100, allow_inf_nan=False)
    poissons_ratio: float = Field(gt=-1, lt=0.5)
    density_kg_m3: float = Field(gt=0, le=5000)

    @property
    def youngs_modulus_MPa(self) -> float:
        """E [MPa] = E [GPa] · 1000."""
        return self.youngs_modulus_GPa * 1e3

    @property
    def density_t_mm3(self) -> float:
        """ρ [tonne/mm³] = ρ [kg/m³] · 1e-12."""
        return self.density_kg_m3 * 1e-12


TABLE_3_1 = {"cortical": MaterialSpec(youngs_modulus_GPa=16.0, poissons_ratio=0.4, density_kg_m3=1700),
             "cancellous": MaterialSpec(youngs_modulus_GPa=0.5, poissons_ratio=0.15, density_kg_m3=320)}


class MaterialsSpec(_Section):
    """Per-region materials; keys left out keep their Table 3-1 values."""

    cortical: MaterialSpec = TABLE_3_1["cortical"]
    cancellous: MaterialSpec = TABLE_3_1["cancellous"]
    cortical_model: Literal["isotropic", "transversely_isotropic"] = "isotropic"

    @model_validator(mode="before")
    @classmethod
    def _fill_from_table_3_1(cls, data):
        if isinstance(data, dict):
            data = dict(data)
            for name, default in TABLE_3_1.items():
                if isinstance(data.get(name), dict):
                    data[name] = {**default.model_dump(), **data[name]}
        return data


class ClampSpec(_Section):
    """Surface nodes within ``length_mm`` of each end, along the long axis, are fixed."""

    length_mm: PositiveMM = 20.0


class SiteSpec(_Section):
    """Drill site: fraction of the length from the proximal end and the side the drill enters
    from: ``"anterior"`` enters the anterior cortex and drills posteriorly; a vector names the
    entry side the same way, pointing from the bone towards the drill (docs/meshing.md)."""

    name: str = "mid-diaphysis"
    position: float = Field(0.5, gt=0, lt=1)
    direction: Union[Literal["anterior", "posterior", "lateral", "medial"], Vector3] = "anterior"


class DrillSpec(_Section):
    diameter_mm: float = Field(2.7, gt=0, le=20)
    point_angle_deg: float = Field(90.0, gt=0, lt=180)
    wall_mm: float | None = Field(None, gt=0, le=20)


class DrillingSpec(_Section):
    """Operating point and load models. ``depth_mm = "cortex"`` drills the local cortex.
    ``mu_f``/``mu_w`` replace the bone set's power law (e.g. to sweep friction);
    ``load_scale`` multiplies the thrust and torque of both loadings (sensitivity studies,
    safety factors; 0 gives the unloaded bone)."""

    feed_mm_s: float = Field(2.0, gt=0, le=50)
    spindle_rpm: float = Field(1500.0, gt=0, le=100_000)
    bone: str = "bovine"
    mu_f: float | None = Field(None, gt=0, le=5)
    mu_w: float | None = Field(None, gt=0, le=10)
    depth_mm: Union[Literal["cortex"], Annotated[float, Field(gt=0, le=100)]] = 6.0
    load_scale: float = Field(1.0, ge=0, le=100)


class TimeSpec(_Section):
    end_s: float = Field(3.0, gt=0, le=3600)
    step_s: float = Field(0.1, gt=0)

    @model_validator(mode="after")
    def _step_fits(self):
        if self.step_s > self.end_s:
            raise ValueError(f"step_s = {self.step_s} s is larger than the span end_s = {self.end_s} s")
        return self


class AnalysisSpec(_Section):
    transient: bool = True
    rayleigh_alpha_per_s: float = Field(0.0, ge=0)
    rayleigh_beta_s: float = Field(0.0, ge=0)
    modes: int = Field(6, ge=0, le=100)
    exclusion_radius_mm: PositiveMM = 4.0


class OutputSpec(_Section):
    """What a run writes besides summary.json, timeseries.csv and report.md."""

    fields: bool = True
    fields_every: int = Field(5, ge=1, description="write fields every n-th time step (and the last)")
    figures: bool = True
    screenshot: bool = True


class Case(_Section):
    """A whole study case. ``source`` is the file it came from (not a TOML key)."""

    name: str
    description: str = ""
    geometry: GeometrySpec = GeometrySpec()
    mesh: MeshSpec = MeshSpec()
    materials: MaterialsSpec = MaterialsSpec()
    clamps: ClampSpec = ClampSpec()
    site: SiteSpec = SiteSpec()
    drill: DrillSpec = DrillSpec()
    drilling: DrillingSpec = DrillingSpec()
    time: TimeSpec = TimeSpec()
    analysis: AnalysisSpec = AnalysisSpec()
    output: OutputSpec = OutputSpec()
    source: Path | None = Field(None, exclude=True)

    @field_validator("name")
    @classmethod
    def _name_is_a_folder_name(cls, name: str) -> str:
        if not re.fullmatch(r"[A-Za-z0-9._-]+", name):
            raise ValueError("name may contain only letters, digits, '.', '_' and '-' (it names the results folder)")
        return name

    @field_validator("geometry")
    @classmethod
    def _surface_nonempty(cls, g: GeometrySpec) -> GeometrySpec:
        if not g.surface.strip():
            raise ValueError("geometry.surface must be 'builtin' or a path to a surface file")
        return g

    def surface_path(self) -> Path | None:
        """The surface file, resolved against the case file's folder; None for the built-in femur."""
        if self.geometry.surface == "builtin":
            return None
        path = Path(self.geometry.surface).expanduser()
        if not path.is_absolute() and self.source is not None:
            path = self.source.parent / path
        return path


def _key_line(text: str, keys: list[str]) -> int | None:
    """Best-effort 1-based line of the TOML key path ``keys``, else of its nearest table."""
    table: list[str] = []
    best, best_depth = None, 0
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        header = re.fullmatch(r"\[\[?\s*([^\]]+?)\s*\]\]?", line)
        if header:
            table = [part.strip().strip('"') for part in header.group(1).split(".")]
            if table == keys[: len(table)] and len(table) > best_depth:
                best, best_depth = number, len(table)
            continue
        match = re.match(r"([A-Za-z0-9_.\"-]+)\s*=", line)
        if match:
            path = table + [part.strip().strip('"') for part in match.group(1).split(".")]
            if path == keys[: len(path)] and len(path) > best_depth:
                best, best_depth = number, len(path)
    return best


def _field_path(loc: tuple, model: type[BaseModel]) -> tuple[list[str], type[BaseModel] | None]:
    """The TOML key path of an error location, without pydantic's union-member tags,
    and the model owning the last key."""
    keys: list[str] = []
    owner: type[BaseModel] | None = model
    for item in loc:
        if owner is not None and isinstance(item, str) and item in owner.model_fields:
            keys.append(item)
            annotation = owner.model_fields[item].annotation
            owner = annotation if isinstance(annotation, type) and issubclass(annotation, BaseModel) else None
        elif isinstance(item, int) and owner is not None:
            keys.append(str(item))
        elif owner is not None and isinstance(item, str):  # an unknown key
            keys.append(item)
            return keys, owner
    return keys, None


def _describe(errors: list[dict]) -> tuple[list[str], str]:
    """The key path and a one-line message for the first problem (union members merged)."""
    keys, owner = _field_path(errors[0]["loc"], Case)
    same = [e for e in errors if _field_path(e["loc"], Case)[0] == keys]
    dotted = ".".join(keys) or "(file)"
    if errors[0]["type"] == "extra_forbidden":
        valid = [v for v in (owner.model_fields if owner else []) if v != "source"]
        near = difflib.get_close_matches(keys[-1], valid, n=1)
        hint = f"did you mean '{near[0]}'?" if near else f"valid keys: {', '.join(valid)}"
        return keys, f"{dotted}: unknown key; {hint}"
    messages = list(dict.fromkeys(e["msg"].replace("Value error, ", "") for e in same))
    expected = ", or ".join([messages[0]] + [m.removeprefix("Input should be ") for m in messages[1:]])
    got = errors[0].get("input")
    shown = "" if isinstance(got, dict) or errors[0]["type"] == "missing" else f", got {got!r}"
    return keys, f"{dotted}: {expected}{shown}"


def parse_case(text: str, source: Path | None = None) -> Case:
    """Validate case-file text; raise :class:`UserError` naming the key and line."""
    where = str(source) if source else "<case>"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{where}: TOML syntax error: {exc}") from None
    if "name" not in data and source is not None:
        data["name"] = source.stem
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        errors = exc.errors()
        keys, message = _describe(errors)
        line = _key_line(text, keys)
        others = {tuple(_field_path(e["loc"], Case)[0]) for e in errors} - {tuple(keys)}
        more = f" (and {len(others)} more problem{'s' if len(others) > 1 else ''})" if others else ""
        raise UserError(f"{where}{f':{line}' if line else ''}: {message}{more}") from None
    return case.model_copy(update={"source": source})


def with_overrides(case: Case, overrides: dict) -> Case:
    """A copy of ``case`` with dotted keys replaced (``{"drilling.feed_mm_s": 1.5}``), validated."""
    data = case.model_dump(mode="json", exclude={"source"})
    for dotted, value in overrides.items():
        node = data
        *parents, last = dotted.split(".")
        for key in parents:
            if not isinstance(node.get(key), dict):
                raise UserError(f"sweep key '{dotted}': '{key}' is not a section of a case file")
            node = node[key]
        if last not in node:
            near = difflib.get_close_matches(last, list(node), n=1)
            hint = f"; did you mean '{'.'.join(parents + [near[0]])}'?" if near else ""
            raise UserError(f"sweep key '{dotted}' is not a case-file key{hint}")
        node[last] = value
    try:
        updated = Case.model_validate(data)
    except ValidationError as exc:
        keys, message = _describe(exc.errors())
        raise UserError(f"sweep value out of range: {message}") from None
    return updated.model_copy(update={"source": case.source})


def check_references(case: Case) -> None:
    """Fail now, before any work, if the surface file or the bone set does not exist."""
    from femstudy.drilling.friction import load_bone_set
    from femstudy.meshing.surface import check_surface_file

    where = str(case.source) if case.source else "<case>"
    surface = case.surface_path()
    if surface is not None:
        try:
            check_surface_file(surface)
        except UserError as exc:
            line = _key_line(case.source.read_text(encoding="utf-8"), ["geometry", "surface"]) if case.source else None
            hint = (" (paths are relative to the case file's folder; use \"builtin\" for the built-in femur)"
                    if not surface.exists() else "")
            raise UserError(f"{where}{f':{line}' if line else ''}: geometry.surface: {exc}{hint}") from None
    try:
        load_bone_set(case.drilling.bone)
    except UserError as exc:
        raise UserError(f"{where}: drilling.bone: {exc}") from None


def load_case(path: str | Path) -> Case:
    """Read and validate a case file, including the files and bone set it refers to."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"case file {path} does not exist")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read case file {path}: {exc}") from None
    case = parse_case(text, path)
    check_references(case)
    return case
