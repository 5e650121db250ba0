"""Case files: TOML checked against a schema, with errors that name the key and the line.

Every section has defaults that reproduce the thesis's FE set-up (§3.3, §5.9). Units are
in the key names; material properties are given in the units the thesis tables use (GPa,
kg/m³) and converted to the solver's MPa and tonne/mm³ by :class:`MaterialSpec`.

Values are checked strictly: numbers must be finite TOML numbers (``true`` or ``"2.0"`` is
not a feed), and every range follows from what the quantity can be on a femur; the bounds
and their reasons are listed in docs/checks.md.
"""

from __future__ import annotations

import difflib
import math
import re
from pathlib import Path
from typing import Annotated, Literal, Union

from pydantic import (BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, field_validator,
                      model_validator)

from femstudy import thesis
from femstudy.errors import UserError
from femstudy.materials import BoneMaterials, IsotropicMaterial
from femstudy.schema import describe, key_line, parse_toml

PositiveMM = Annotated[float, Field(gt=0, allow_inf_nan=False)]


def _three_numbers(value):
    ok = (isinstance(value, (list, tuple)) and len(value) == 3
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    if not ok:
        raise ValueError("a non-zero vector of three numbers [x, y, z]")
    if not all(math.isfinite(v) for v in value):
        raise ValueError("a vector of three finite numbers [x, y, z] (it holds nan or inf)")
    if not any(v != 0 for v in value):
        raise ValueError("a non-zero vector of three numbers [x, y, z]")
    return tuple(float(v) for v in value)


Vector3 = Annotated[tuple[float, float, float], BeforeValidator(_three_numbers)]
ANATOMICAL_DIRECTIONS = ("anterior", "posterior", "lateral", "medial")
#: A twist drill advances at most this far per turn [mm/rev] (surgical drilling: 0.01-0.2).
MAX_FEED_PER_REV_MM = 1.0
#: Largest TetWild target edge [mm] (:class:`MeshSpec`).
MAX_MESH_SIZE_MM = 64.0
#: A case file is a short text: larger files are refused before they are read.
MAX_CASE_BYTES = 1 << 20


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


class CortexSpec(_Section):
    """Cortical shell thickness along the long axis [mm]."""

    midshaft_mm: float = Field(6.0, gt=0, le=20)
    epiphysis_mm: float = Field(2.0, gt=0, le=20)


class CanalSpec(_Section):
    """Empty medullary canal: diameter at mid-shaft and its extent as fractions of length
    measured from the proximal end (0 = top of the head, 1 = bottom of the condyles).

    Cancellous bone between the canal and the cortex thinner than ``min_cancellous_mm`` is
    not kept: the canal then reaches the cortex (docs/meshing.md)."""

    diameter_mm: float = Field(13.0, gt=0, le=50)
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
    """TetWild target edge lengths [mm] and element order. A global size beyond 64 mm, more
    than twice a femoral shaft's width, describes no bone (and TetWild then runs for minutes:
    more than 300 s at 500 mm against 34 s at 64 mm, docs/checks.md); a site size below
    0.05 mm is finer than bone's microstructure, where a continuum model no longer holds."""

    size_mm: float = Field(8.0, gt=0, le=MAX_MESH_SIZE_MM)
    refine: Literal["site", "uniform"] = "site"
    site_size_mm: float = Field(1.0, ge=0.05, le=MAX_MESH_SIZE_MM)
    site_radius_mm: float = Field(12.0, gt=0, le=200)
    envelope: float = Field(1e-3, gt=0, le=0.05)
    order: Literal[1, 2] = 2


class MaterialSpec(_Section):
    """Isotropic linear elastic material in the thesis's units (Table 3-1). Bone's moduli
    lie between about 10 MPa (osteoporotic cancellous) and 30 GPa (cortical), its density
    between about 100 and 2100 kg/m³; the ranges allow an order of magnitude either side."""

    youngs_modulus_GPa: float = Field(ge=0.001, le=100, allow_inf_nan=False)
    poissons_ratio: float = Field(gt=-1, lt=0.5)
    density_kg_m3: float = Field(ge=10, le=5000)

    @property
    def youngs_modulus_MPa(self) -> float:
        """E [MPa] = E [GPa] · 1000."""
        return self.youngs_modulus_GPa * 1e3

    @property
    def density_t_mm3(self) -> float:
        """ρ [tonne/mm³] = ρ [kg/m³] · 1e-12."""
        return self.density_kg_m3 * 1e-12

    def to_fe(self) -> IsotropicMaterial:
        """The solver's record, in MPa and tonne/mm³."""
        return IsotropicMaterial(self.youngs_modulus_MPa, self.poissons_ratio, self.density_t_mm3)


TABLE_3_1 = {name: MaterialSpec(youngs_modulus_GPa=m["E_MPa"] / 1e3, poissons_ratio=m["nu"],
                                density_kg_m3=round(m["density_t_mm3"] * 1e12, 6))
             for name, m in thesis.TABLE_3_1.items()}


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

    def to_fe(self) -> BoneMaterials:
        """The solver's material records."""
        return BoneMaterials(self.cortical.to_fe(), self.cancellous.to_fe(), self.cortical_model)


class ClampSpec(_Section):
    """Surface nodes within ``length_mm`` of each end, along the long axis, are fixed."""

    length_mm: float = Field(20.0, ge=1, le=1000)


class SiteSpec(_Section):
    """Drill site: fraction of the length from the proximal end and the side the drill enters
    from: ``"anterior"`` enters the anterior cortex and drills posteriorly; a vector names the
    entry side the same way, pointing from the bone towards the drill (docs/meshing.md)."""

    name: str = "mid-diaphysis"
    position: float = Field(0.5, gt=0, lt=1)
    direction: Union[Literal["anterior", "posterior", "lateral", "medial"], Vector3] = "anterior"


class DrillSpec(_Section):
    diameter_mm: float = Field(thesis.DRILL_DIAMETER_MM, gt=0, le=20)
    point_angle_deg: float = Field(thesis.DRILL_POINT_ANGLE_DEG, gt=0, lt=180)
    wall_mm: float | None = Field(None, gt=0, le=20)


class DrillingSpec(_Section):
    """Operating point and load models. ``model`` names the dynamic loading's load model
    (:mod:`femstudy.drilling.registry`: "clogging", cutting + chip evacuation, by default;
    "allotta", cutting alone; any registered model fit for a study); the static loading is
    always Allotta's full-engagement load. ``depth_mm = "cortex"`` drills the local cortex.
    ``bone`` names the friction calibration: "human" (thesis Table 5-11; the default, femurs
    here being human), "bovine" (Table 5-1), "human-printed" (the thesis's printed Eqs
    5.8/5.9) or a calibrated set. ``mu_f``/``mu_w`` replace its power law (e.g. to sweep friction);
    ``load_scale`` multiplies the thrust and torque of both loadings (sensitivity studies,
    safety factors; 0 gives the unloaded bone). ``flute_oscillation`` is the relative
    amplitude of the per-flute oscillation and ``breakthrough_release_s`` the time over which
    the chip-evacuation load is released at breakthrough ("flute": one flute passage); both
    enter the resolved transient only (docs/load-models.md)."""

    model: str = "clogging"
    feed_mm_s: float = Field(2.0, ge=0.01, le=50)
    spindle_rpm: float = Field(1500.0, ge=10, le=100_000)
    bone: str = "human"
    mu_f: float | None = Field(None, gt=0, le=5)
    mu_w: float | None = Field(None, gt=0, le=10)
    depth_mm: Union[Literal["cortex"], Annotated[float, Field(ge=0.1, le=100)]] = 6.0
    load_scale: float = Field(1.0, ge=0, le=100)
    flute_oscillation: float = Field(0.1, ge=0, lt=1)
    breakthrough_release_s: Union[Literal["flute"], Annotated[float, Field(gt=0, le=10)]] = "flute"

    @field_validator("model")
    @classmethod
    def _registered_model(cls, name: str) -> str:
        from femstudy.drilling import registry

        choices = registry.names("study")
        if name not in choices:
            raise ValueError(f"'{name}' is not a load model for a study: choose one of {', '.join(choices)}")
        return name

    @model_validator(mode="after")
    def _drills(self):
        a = 60.0 * self.feed_mm_s / self.spindle_rpm
        if a > MAX_FEED_PER_REV_MM:
            raise ValueError(f"feed_mm_s = {self.feed_mm_s:g} mm/s at spindle_rpm = {self.spindle_rpm:g} advances the "
                             f"drill {a:.3g} mm per turn; a twist drill cuts at most {MAX_FEED_PER_REV_MM:g} mm per turn "
                             "(surgical drilling: 0.01-0.2 mm)")
        return self


class LoadsSpec(_Section):
    """Where the drill's loads act. ``application = "hole"`` (the default): the global model
    drives local models of the drilled hole at ``stations`` depth stations, with the cutting
    loads on the drill-point cone and the chip evacuation as wall friction, and the report
    quotes the stresses at ``distances_mm`` from the hole wall (``headline_distance_mm`` the
    headline) and the maximum outside exclusion radii (docs/hole.md). ``"surface_patch"``:
    the loads on a disk of the outer surface only, for comparison with the thesis's point-like
    loading (its peak stress under the patch is mesh-dependent). ``refinement``,
    ``submodel_radius_mm`` and ``depth_cap_mm`` set the local model's mesh and extent,
    ``smoothing_mm`` the Gaussian smoothing of the bone surfaces it sees (0: none).
    ``verify``: judge every near-hole measure in the run, by two coarser refinements of the local
    models and replicate placements (:mod:`femstudy.study.verification`); its verdicts and
    bands go with every stress and margin quoted. ``ligament_mm``: the least bone left ahead of
    the deepest drill tip. ``cone_traction``: how the cutting loads spread over the drill-point
    cone, "allotta" (a constant force per unit lip length, traction ∝ 1/r: Eqs 2.18–2.19) or
    "uniform" (docs/hole.md)."""

    application: Literal["hole", "surface_patch"] = "hole"
    stations: int = Field(3, ge=1, le=20)
    distances_mm: list[Annotated[float, Field(gt=0, le=50)]] = Field(
        default_factory=lambda: [0.5, 1.0, 2.0, 5.0], min_length=1, max_length=20)
    headline_distance_mm: PositiveMM = 1.0
    exclusion_radii_mm: list[Annotated[float, Field(gt=0, le=50)]] = Field(
        default_factory=lambda: [0.5, 1.0, 2.0, 3.0, 4.0], min_length=1, max_length=20)
    exclusion_radius_mm: PositiveMM = 1.0
    refinement: float = Field(2 / 3, gt=0, le=4)
    submodel_radius_mm: float = Field(8.0, gt=2, le=50)
    depth_cap_mm: float = Field(12.0, gt=0, le=100)
    smoothing_mm: float = Field(1.0, ge=0, le=5)
    ligament_mm: float = Field(0.5, gt=0, le=5)
    cone_traction: Literal["allotta", "uniform"] = "allotta"
    verify: bool = True

    @model_validator(mode="before")
    @classmethod
    def _record_no_longer_read(cls, data):
        if isinstance(data, dict) and "convergence" in data:
            import logging

            data = {k: v for k, v in data.items() if k != "convergence"}
            logging.getLogger(__name__).warning(
                "loads.convergence is no longer read: a run verifies its near-hole measures itself (loads.verify)")
        return data

    @model_validator(mode="after")
    def _quoted_values_are_measured(self):
        if self.headline_distance_mm not in self.distances_mm:
            raise ValueError(f"headline_distance_mm = {self.headline_distance_mm} is not one of distances_mm")
        if self.exclusion_radius_mm not in self.exclusion_radii_mm:
            raise ValueError(f"exclusion_radius_mm = {self.exclusion_radius_mm} is not one of exclusion_radii_mm")
        return self

    def hole_options(self):
        """The library's :class:`femstudy.hole.study.HoleOptions`."""
        from femstudy.hole.study import HoleOptions

        return HoleOptions(stations=self.stations, distances_mm=tuple(self.distances_mm),
                           exclusion_radii_mm=tuple(self.exclusion_radii_mm),
                           exclusion_radius_mm=self.exclusion_radius_mm, headline_distance_mm=self.headline_distance_mm,
                           refinement=self.refinement, submodel_radius_mm=self.submodel_radius_mm,
                           depth_cap_mm=self.depth_cap_mm, smoothing_mm=self.smoothing_mm,
                           ligament_mm=self.ligament_mm, cone_traction=self.cone_traction)


class TimeSpec(_Section):
    end_s: float = Field(3.0, gt=0, le=3600)
    step_s: float = Field(0.1, ge=1e-6)

    @model_validator(mode="after")
    def _step_fits(self):
        if self.step_s > self.end_s:
            raise ValueError(f"step_s = {self.step_s} s is larger than the span end_s = {self.end_s} s")
        return self


class AnalysisSpec(_Section):
    """``resolved`` adds a transient whose step resolves the lowest mode
    (``steps_per_period`` steps per period), with the per-flute oscillation and breakthrough
    release, from ``resolved_lead_s`` before breakthrough (started from the quasi-static state
    there) to 0.1 s past the release: the dynamic amplification near the peak loads.
    ``sensitivity`` adds the one-at-a-time table of how much each modelling choice (clamp
    length, cut radius, ligament rule, cortex model, cone traction, cortical modulus) moves the
    answers (:mod:`femstudy.study.sensitivity`)."""

    transient: bool = True
    rayleigh_alpha_per_s: float = Field(0.0, ge=0, le=1e4)
    rayleigh_beta_s: float = Field(0.0, ge=0, le=1e-3)
    modes: int = Field(6, ge=0, le=100)
    exclusion_radius_mm: float = Field(4.0, gt=0, le=100)
    resolved: bool = True
    steps_per_period: int = Field(20, ge=10, le=200)
    resolved_lead_s: float = Field(0.5, gt=0, le=3600)
    sensitivity: bool = True


class OutputSpec(_Section):
    """What a run writes besides summary.json, timeseries.csv and report.md."""

    fields: bool = True
    fields_every: int = Field(5, ge=1, le=1_000_000, description="write fields every n-th time step (and the last)")
    figures: bool = True
    screenshot: bool = True


class InputSpec(_Section):
    """One uncertain input's distribution (docs/uncertainty.md): ``normal`` (mean, sd),
    ``lognormal`` (median, sigma_ln), ``uniform`` (low, high), ``discrete`` (equally likely
    ``values``) or ``fixed`` (value), in the unit the input's name carries (a ``*_factor``
    multiplies the case's value), and its source."""

    distribution: Literal["normal", "lognormal", "uniform", "discrete", "fixed"]
    mean: float | None = None
    sd: float | None = Field(None, gt=0)
    median: float | None = Field(None, gt=0)
    sigma_ln: float | None = Field(None, gt=0)
    low: float | None = None
    high: float | None = None
    value: float | None = None
    values: list[float] | None = Field(None, min_length=1)
    source: str = "case file"

    @model_validator(mode="after")
    def _parameters_given(self):
        need = {"normal": ("mean", "sd"), "lognormal": ("median", "sigma_ln"), "uniform": ("low", "high"),
                "discrete": ("values",), "fixed": ("value",)}[self.distribution]
        missing = [k for k in need if getattr(self, k) is None]
        if missing:
            raise ValueError(f"a {self.distribution} distribution needs {' and '.join(need)}")
        if self.distribution == "uniform" and not self.low < self.high:
            raise ValueError("uniform: low must be smaller than high")
        return self

    def to_distribution(self):
        """The library's :class:`femstudy.distributions.Distribution`."""
        from femstudy.distributions import Distribution

        if self.distribution == "discrete":
            return Distribution("discrete", tuple(float(v) for v in self.values), self.source)
        keys = {"normal": ("mean", "sd"), "lognormal": ("median", "sigma_ln"), "uniform": ("low", "high"),
                "fixed": ("value",)}[self.distribution]
        return Distribution(self.distribution, tuple(float(getattr(self, k)) for k in keys), self.source)


class UncertaintySpec(_Section):
    """``femstudy uncertainty`` (docs/uncertainty.md): the inputs that vary, their distributions
    where they differ from the cited defaults, the sampling (``montecarlo``: ``samples`` random
    draws; ``sobol``: Saltelli's design of ``samples`` base samples, N(D + 2) evaluations) and
    how many samples also run the hole models (``hole_samples``)."""

    inputs: list[str] = Field(default_factory=lambda: [
        "mu_f_factor", "mu_w_factor", "cutting_force_factor", "feed_mm_s", "spindle_rpm", "depth_mm",
        "cortical_modulus_factor", "cancellous_modulus_factor", "clamp_length_mm"], min_length=1)
    distributions: dict[str, InputSpec] = Field(default_factory=dict)
    method: Literal["montecarlo", "sobol"] = "montecarlo"
    samples: int = Field(1024, ge=8, le=1_000_000)
    seed: int = Field(0, ge=0)
    hole_samples: int = Field(16, ge=0, le=100_000)

    @model_validator(mode="after")
    def _known_inputs(self):
        from femstudy.distributions import INPUTS

        unknown = sorted((set(self.inputs) | set(self.distributions)) - set(INPUTS))
        if unknown:
            raise ValueError(f"unknown uncertain input(s) {', '.join(unknown)}: choose from {', '.join(INPUTS)}")
        return self


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
    loads: LoadsSpec = LoadsSpec()
    time: TimeSpec = TimeSpec()
    analysis: AnalysisSpec = AnalysisSpec()
    output: OutputSpec = OutputSpec()
    uncertainty: UncertaintySpec = UncertaintySpec()
    source: Path | None = Field(None, exclude=True)

    @field_validator("name")
    @classmethod
    def _name_is_a_folder_name(cls, name: str) -> str:
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}", name):
            raise ValueError("name may contain only letters, digits, '.', '_' and '-', must begin with a letter or "
                             "digit and have at most 100 characters (it names the results folder)")
        return name

    @field_validator("geometry")
    @classmethod
    def _surface_nonempty(cls, g: GeometrySpec) -> GeometrySpec:
        if not g.surface.strip():
            raise ValueError("geometry.surface must be 'builtin' or a path to a surface file")
        return g

    def surface_path(self) -> Path | None:
        """The surface file, resolved against the case file's folder; None for the built-in femur."""
        return None if self.geometry.surface == "builtin" else self._resolve(self.geometry.surface)

    def _resolve(self, name: str) -> Path:
        path = Path(name).expanduser()
        return path if path.is_absolute() or self.source is None else self.source.parent / path


def parse_case(text: str, source: Path | None = None) -> Case:
    """Validate case-file text; raise :class:`UserError` naming the key and line.

    Parameters
    ----------
    text : str
        TOML (every section optional; see :class:`Case`).
    source : Path, optional
        The file it came from: relative paths in it are resolved from its folder, and a
        missing ``name`` is the file's stem.

    Returns
    -------
    Case

    Examples
    --------
    >>> parse_case('name = "mid"\\n[site]\\nposition = 0.5').site.position
    0.5
    """
    def defaults(data: dict) -> dict:
        if "name" not in data and source is not None:
            data["name"] = source.stem
        return data

    case = parse_toml(text, Case, str(source) if source else "<case>", defaults)
    return case.model_copy(update={"source": source})


def with_overrides(case: Case, overrides: dict, what: str = "sweep") -> Case:
    """A copy of ``case`` with dotted keys replaced (``{"drilling.feed_mm_s": 1.5}``), validated
    like a case file's values; ``what`` names the overrides' origin in error messages (a sweep,
    an option such as --mesh-size)."""
    data = case.model_dump(mode="json", exclude={"source"})
    for dotted, value in overrides.items():
        node = data
        *parents, last = dotted.split(".")
        for key in parents:
            if not isinstance(node.get(key), dict):
                raise UserError(f"{what} key '{dotted}': '{key}' is not a section of a case file")
            node = node[key]
        if last not in node:
            near = difflib.get_close_matches(last, list(node), n=1)
            hint = f"; did you mean '{'.'.join(parents + [near[0]])}'?" if near else ""
            raise UserError(f"{what} key '{dotted}' is not a case-file key{hint}")
        node[last] = value
    try:
        updated = Case.model_validate(data)
    except ValidationError as exc:
        _, message = describe(exc.errors(), Case)
        raise UserError(f"{what} value out of range: {message}") from None
    return updated.model_copy(update={"source": case.source})


def check_references(case: Case, bones_dir: Path | None = None) -> None:
    """Fail now, before any work, if the surface file or the bone set (looked up in
    ``bones_dir`` besides the built-in ones) does not exist."""
    from femstudy.drilling.friction import load_bone_set
    from femstudy.meshing.surface import check_surface_file

    where = str(case.source) if case.source else "<case>"
    surface = case.surface_path()
    if surface is not None:
        try:
            check_surface_file(surface)
        except UserError as exc:
            line = key_line(case.source.read_text(encoding="utf-8"), ["geometry", "surface"]) if case.source else None
            hint = (" (paths are relative to the case file's folder; use \"builtin\" for the built-in femur)"
                    if not surface.exists() else "")
            raise UserError(f"{where}{f':{line}' if line else ''}: geometry.surface: {exc}{hint}") from None
    try:
        load_bone_set(case.drilling.bone, bones_dir)
    except UserError as exc:
        raise UserError(f"{where}: drilling.bone: {exc}") from None


def load_case(path: str | Path, bones_dir: Path | None = None) -> Case:
    """Read and validate a case file, including the files and bone set it refers to.

    Parameters
    ----------
    path : str or Path
        The TOML case file.
    bones_dir : Path, optional
        Folder of calibrated bone sets (default: the user's femstudy data folder).

    Returns
    -------
    Case

    Examples
    --------
    >>> case = load_case("cases/middiaphysis.toml")   # doctest: +SKIP
    >>> case.drilling.feed_mm_s                        # doctest: +SKIP
    2.0
    """
    path = Path(path)
    if path.is_dir():
        inside = sorted(p.name for p in path.glob("*.toml"))[:3]
        hint = f" (it holds {', '.join(inside)}: name one of them)" if inside else ""
        raise UserError(f"case file {path} is a folder, not a case file{hint}")
    if not path.exists():
        raise UserError(f"case file {path} does not exist")
    if not path.is_file():
        raise UserError(f"case file {path} is not a regular file (a device or a pipe?); give a TOML file")
    if path.stat().st_size > MAX_CASE_BYTES:
        raise UserError(f"case file {path} is {path.stat().st_size:,} bytes; a case file is a short TOML text "
                        f"(at most {MAX_CASE_BYTES // 1024} kB)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read case file {path}: {exc}") from None
    case = parse_case(text, path)
    check_references(case, bones_dir)
    return case
