"""Stresses near the drilled hole of a femur: the global model drives local hole models.

Its inputs are plain values (:class:`HoleInputs`: drill, materials, element order, clamped
length, the loads at each tip depth), the meshed femur and the global system; it knows
nothing of case files or studies.

One-way submodelling (docs/hole.md). The global femur model (no hole) is solved for a unit
thrust and a unit torque on its surface patch; its displacement under the loading at a
station's tip depth is Σ amplitude × unit field. At each of a few depth stations the local
column model around the drill axis (:mod:`femstudy.hole.mesh`, the hole drilled to that tip
depth) takes those displacements on its cut faces (:mod:`femstudy.hole.coupling`) and the
drill's loads on its hole — cutting thrust and torque on the cone, the chip-evacuation torque
as wall friction and its thrust on the bottom (:mod:`femstudy.hole.loads`) — with the same
resultants as the patch. Each station costs one assembly and one factorisation; its loadings
(dynamic: the study's load model at that depth, :class:`StationLoad`; static: Allotta's
full-engagement load, all of it cutting) are two right-hand sides. The measures
(:mod:`femstudy.hole.measures`) are taken at stated distances from the hole wall and outside
exclusion radii. Units: mm, N, N·mm, MPa, s.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from femstudy.drilling.drill import Drill
from femstudy.errors import UserError, require
from femstudy.materials import BoneMaterials
from femstudy.hole.coupling import cut_boundary
from femstudy.hole.dirichlet import factorize_prescribed
from femstudy.hole.femur import femur_columns, smooth_columns, surface_columns
from femstudy.hole.frame import HoleFrame
from femstudy.hole.loads import hole_loads
from femstudy.hole.measures import HoleMeasure, distance_measures, distance_samples, exclusion_measures
from femstudy.hole.mesh import Resolution, hole_mesh
from femstudy.hole.probe import MeshLocator

if TYPE_CHECKING:
    from femstudy.hole.femur import FemurColumns, SmoothColumns, SurfaceColumns

log = logging.getLogger(__name__)

LOADINGS = ("dynamic", "static")


@dataclass(frozen=True)
class HoleOptions:
    """How the hole models are built and measured (lengths in mm).

    stations : number of depth stations, tips at k/n of the deepest tip (k = 1..n)
    ligament_mm : least bone left ahead of the deepest tip along the axis: the deepest tip is the
        drilled depth, but no deeper than this short of the local model's own bottom surface on
        the axis (breakthrough itself, a vanishing ligament, is a fracture problem, not a stress
        measure; measured on the local model's surfaces, the ligament is the same on every
        global mesh)
    distances_mm : distances from the hole surface of the measures
    exclusion_radii_mm : exclusion radii of the sensitivity table; ``exclusion_radius_mm`` the quoted one
    headline_distance_mm : the distance whose von Mises stress a report quotes
    refinement : :class:`femstudy.hole.mesh.Resolution` refinement; the default 2/3 has 0.45 mm
        elements at the wall and 0.15 mm layers through the ligament ahead of the deepest tip
        (docs/hole.md: its measures lie within 1 % of refinement 1.5 on both femurs)
    submodel_radius_mm, depth_cap_mm : extent of the local model (radius about the axis, depth below the top)
    cut_margin_mm : quadrature points this close to a cut-face node are not in the exclusion measures
    smoothing_mm : Gaussian smoothing length of the bone's top and bottom surfaces seen by the
        local model (:func:`femstudy.hole.femur.smooth_columns`); 0 ray-casts every column on the
        global facets
    rotation_deg : turns the local mesh about the drill axis (its placement; for measuring the
        discretisation noise of a maximum, as two meshes of one size placed differently)
    cone_traction : how the cutting loads spread over the drill-point cone, "allotta" or
        "uniform" (:func:`femstudy.hole.loads.hole_loads`)
    """

    stations: int = 3
    ligament_mm: float = 0.5
    distances_mm: tuple = (0.5, 1.0, 2.0, 5.0)
    exclusion_radii_mm: tuple = (0.5, 1.0, 2.0, 3.0, 4.0)
    exclusion_radius_mm: float = 1.0
    headline_distance_mm: float = 1.0
    refinement: float = 2 / 3
    submodel_radius_mm: float = 8.0
    depth_cap_mm: float = 12.0
    cut_margin_mm: float = 2.0
    smoothing_mm: float = 1.0
    rotation_deg: float = 0.0
    cone_traction: str = "allotta"


@dataclass(frozen=True)
class StationLoad:
    """The dynamic loading when the drill tip is at one depth: time [s] and the amplitudes of its
    cutting part (thrust [N], torque [N·mm] on the cone) and chip-evacuation part (thrust on the
    bottom, torque as wall friction) (:func:`femstudy.drilling.load_parts`)."""

    time_s: float
    cutting_thrust_N: float
    cutting_torque_Nmm: float
    evacuation_thrust_N: float
    evacuation_torque_Nmm: float


@dataclass(frozen=True)
class HoleInputs:
    """What the hole models take from a study, as plain values.

    drill : the drill (diameter and point angle make the hole)
    materials : the regions' materials
    order : element order of the local models (1 or 2)
    clamp_length_mm : length clamped at each end of the femur, along its long axis (the
        exclusion measures leave it out)
    drilled_depth_mm : the hole's depth (the deepest station's tip, short of the ligament)
    station_load : tip depth [mm] → :class:`StationLoad` of the dynamic loading
    static_load : (thrust [N], torque [N·mm]) of the static loading, all of it cutting
    growth_exponent : p of the chip pressure along the engaged wall (:func:`femstudy.hole.loads.hole_loads`)
    """

    drill: Drill
    materials: BoneMaterials
    order: int
    clamp_length_mm: float
    drilled_depth_mm: float
    station_load: Callable[[float], StationLoad]
    static_load: tuple[float, float]
    growth_exponent: float


@dataclass(frozen=True)
class HoleScenario:
    """An alternative measured on the same local meshes as the study's hole models, for its
    dynamic loading: the global unit fields of another global model (``unit_fields``, (n_dofs,
    2); None: the study's), other materials of the local models (None: the inputs'), another
    spread of the cutting loads over the cone (``cone_traction``; None: the options'), another
    clamped length left out of the exclusion measures (``clamp_length_mm``; None: the inputs'). The
    meshes, the cut nodes' places in the femur mesh and the measures' points are shared; a
    scenario of other materials costs one more factorisation, any other one more right-hand side."""

    name: str
    unit_fields: np.ndarray | None = None
    materials: BoneMaterials | None = None
    cone_traction: str | None = None
    clamp_length_mm: float | None = None


@dataclass(frozen=True)
class StationRun:
    """One station: its loads, its size and cost.

    tip_depth_mm, time_s : the drill tip's depth and the time the dynamic loading reaches it
    cutting_thrust_N, cutting_torque_Nmm, evacuation_thrust_N, evacuation_torque_Nmm : dynamic amplitudes
    dofs : P2 DOFs of the local model; cut_dofs : of them prescribed
    factorisations : of the local model (0 when kept solutions served its solves, femstudy.fe.kept)
    seconds : mesh station + assembly + factorisation + solves + measures [s]
    moved_mm : largest distance a cut node was moved onto the femur mesh
    """

    station: int
    tip_depth_mm: float
    time_s: float
    cutting_thrust_N: float
    cutting_torque_Nmm: float
    evacuation_thrust_N: float
    evacuation_torque_Nmm: float
    dofs: int
    cut_dofs: int
    seconds: float
    moved_mm: float
    factorisations: int


@dataclass(frozen=True)
class HoleResult:
    """Hole-based stresses of a study (docs/hole.md).

    options : :class:`HoleOptions`
    stations : one :class:`StationRun` per station
    measures : every :class:`HoleMeasure` (loading × station × distance or exclusion radius)
    static_load : (thrust_N, torque_Nmm) of the static loading
    mesh_seconds : time to build the column mesh [s]
    axis_bottom_mm : depth of the local model's bottom surface on the drill axis below the entry
        point [mm] (inf: solid bone to the depth cap); minus the deepest tip, the ligament
    bone_axis, bone_axis_evidence : the cortex's material and strength axis at the site and how
        it was found (:class:`HoleSite`)
    scenarios : name → the dynamic loading's measures of each :class:`HoleScenario` asked for
    """

    options: HoleOptions
    stations: tuple
    measures: tuple
    static_load: tuple
    mesh_seconds: float
    axis_bottom_mm: float
    bone_axis: tuple = (0.0, 0.0, 1.0)
    bone_axis_evidence: dict | None = None
    scenarios: dict | None = None

    @property
    def wall_element_mm(self) -> float:
        """The local model's element size at the hole wall [mm]: its mesh measure for convergence."""
        return float(Resolution(refinement=self.options.refinement).scaled["wall_mm"])

    def worst(self, kind: str, radius_mm: float, loading: str = "dynamic") -> HoleMeasure:
        """The station with the largest von Mises stress for one kind, radius and loading."""
        found = [m for m in self.measures if m.kind == kind and m.loading == loading
                 and abs(m.radius_mm - radius_mm) < 1e-9 and np.isfinite(m.von_mises_MPa)]
        require(len(found) > 0, f"no hole measure '{kind}' at {radius_mm} mm for the {loading} loading")
        return max(found, key=lambda m: m.von_mises_MPa)

    def headline(self, loading: str = "dynamic") -> HoleMeasure:
        """The quoted stress: the largest von Mises at ``options.headline_distance_mm`` over the stations."""
        return self.worst("distance", self.options.headline_distance_mm, loading)

    def table(self, kind: str) -> list[dict]:
        """Per radius (kind "distance", "wall" or "exclusion"): the worst station's measures of both
        loadings and their ratio (a report row)."""
        radii = self.options.exclusion_radii_mm if kind == "exclusion" else self.options.distances_mm
        rows = []
        for r in radii:
            d, s = self.worst(kind, r, "dynamic"), self.worst(kind, r, "static")
            rows.append({"radius_mm": float(r), "dynamic": d.row(), "static": s.row(),
                         "ratio_dynamic_to_static": d.von_mises_MPa / s.von_mises_MPa if s.von_mises_MPa > 0 else None})
        return rows

    def margins(self) -> dict:
        """Failure margins (:mod:`femstudy.failure`; docs/failure.md): per loading and for every
        near-hole measure (at each distance from the hole, beside its wall, beyond each exclusion
        radius), the smallest load factor to failure over the stations by the stress criteria
        (Tsai–Wu for cortical bone, von Mises against the mean strength for cancellous bone) and
        by the cortical strain criterion, the smaller of the two as the measure's margin, and the
        station where it occurs."""
        from femstudy.failure import CorticalStrainLimits

        out = {"basis": "hole", "criterion": "Tsai-Wu (cortical), von Mises / mean strength (cancellous); "
                                             "maximum principal strain (cortical)",
               "strain_limits": CorticalStrainLimits().source, "source": "femstudy/failure.py, docs/failure.md"}
        sets = ([("distance", r) for r in self.options.distances_mm] + [("wall", r) for r in self.options.distances_mm]
                + [("exclusion", r) for r in self.options.exclusion_radii_mm])
        for loading in LOADINGS:
            rows = []
            for kind, radius in sets:
                found = [m for m in self.measures if m.kind == kind and m.loading == loading
                         and abs(m.radius_mm - radius) < 1e-9]
                margin = [min(m.strength_ratio, m.strain_ratio) for m in found]
                if found and np.isfinite(margin).any():
                    worst = found[int(np.nanargmin(np.where(np.isfinite(margin), margin, np.nan)))]
                    rows.append({"kind": kind, "radius_mm": float(radius), "margin": min(worst.strength_ratio,
                                                                                         worst.strain_ratio),
                                 "strength_ratio": min(m.strength_ratio for m in found),
                                 "strain_ratio": min(m.strain_ratio for m in found),
                                 "governed_by": "strain" if worst.strain_ratio < worst.strength_ratio else "stress",
                                 "station": worst.station, "tip_depth_mm": worst.tip_depth_mm})
            out[loading] = rows
        return out

    def rows(self) -> list[dict]:
        """Every measure as a flat dict (units in the keys), for CSV."""
        return [m.row() for m in self.measures]

    def to_json(self) -> dict:
        """Options, stations, the distance and exclusion tables, and the headline measure."""
        from femstudy.jsonable import jsonable

        return jsonable({"options": dict(self.options.__dict__), "stations": [dict(s.__dict__) for s in self.stations],
                         "static_load": {"thrust_N": self.static_load[0], "torque_Nmm": self.static_load[1]},
                         "mesh_s": self.mesh_seconds, "wall_element_mm": self.wall_element_mm,
                         "axis_bottom_mm": self.axis_bottom_mm if np.isfinite(self.axis_bottom_mm) else None,
                         "bone_axis": list(self.bone_axis), "bone_axis_evidence": self.bone_axis_evidence,
                         "distance": self.table("distance"), "wall": self.table("wall"),
                         "exclusion": self.table("exclusion"),
                         "margins": self.margins(),
                         "headline": {"distance_mm": self.options.headline_distance_mm,
                                      "dynamic": self.headline("dynamic").row(),
                                      "static": self.headline("static").row()}})


def station_tips(options: HoleOptions, drilled_depth_mm: float, cortex_mm: float) -> np.ndarray:
    """Tip depths [mm] of the stations: k/n of the deepest tip, min(drilled depth, cortex −
    ligament) (:class:`HoleOptions`; ``cortex_mm`` the bottom's depth on the axis, inf where
    the bone is solid to the local model's depth cap)."""
    deepest = min(drilled_depth_mm, cortex_mm - options.ligament_mm)
    require(deepest > 0, f"no bone to drill: depth {drilled_depth_mm:g} mm, cortex {cortex_mm:g} mm, "
                         f"ligament {options.ligament_mm:g} mm")
    return deepest * np.arange(1, options.stations + 1) / options.stations


@dataclass(frozen=True)
class HoleSite:
    """The hole's geometry around the drill site, shared by every refinement of the local models.

    frame : the local frame (entry point, drill axis, e1, e2)
    columns : the column tops, bottoms, regions and cortex interface (:mod:`femstudy.hole.femur`)
    options : the options with the local model's radius fitted to the bone
    tips : the stations' drill-tip depths [mm]
    axis_bottom_mm : the local model's bottom on the drill axis below the entry point [mm] (inf:
        solid bone to the depth cap)
    seconds : time to build it [s]
    bone_axis : the bone's local long axis at the site: the transversely isotropic cortex's
        axis and the strength criteria's (:func:`femstudy.meshing.site_surface.local_axis`)
    bone_axis_evidence : how it was found
    """

    frame: HoleFrame
    columns: FemurColumns | SurfaceColumns | SmoothColumns | TurnedColumns
    options: HoleOptions
    tips: np.ndarray
    axis_bottom_mm: float
    seconds: float
    bone_axis: np.ndarray
    bone_axis_evidence: dict[str, Any]

    def with_ligament(self, ligament_mm: float, drilled_depth_mm: float) -> "HoleSite":
        """The same geometry with the stations of another ligament rule (:func:`station_tips`)."""
        options = replace(self.options, ligament_mm=ligament_mm)
        return replace(self, options=options, tips=station_tips(options, drilled_depth_mm, self.axis_bottom_mm))

    def turned(self, degrees: float) -> "HoleSite":
        """The same geometry with the local mesh turned by ``degrees`` about the drill axis (a
        replicate placement of the mesh, for measuring the discretisation noise of a maximum)."""
        c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
        frame = HoleFrame(self.frame.origin, self.frame.axis, c * self.frame.e1 + s * self.frame.e2,
                          c * self.frame.e2 - s * self.frame.e1)
        return replace(self, frame=frame, columns=TurnedColumns(self.columns, frame, c, s),
                       options=replace(self.options, rotation_deg=self.options.rotation_deg + degrees))


@dataclass(frozen=True)
class TurnedColumns:
    """Columns seen in a frame turned about the drill axis: local (x, y) in the turned frame are
    (c x − s y, s x + c y) in the original one."""

    columns: FemurColumns | SurfaceColumns | SmoothColumns | TurnedColumns
    frame: HoleFrame
    c: float
    s: float

    def _xy(self, xy: np.ndarray) -> np.ndarray:
        xy = np.atleast_2d(np.asarray(xy, float))
        return np.column_stack([self.c * xy[:, 0] - self.s * xy[:, 1], self.s * xy[:, 0] + self.c * xy[:, 1]])

    def top(self, xy: np.ndarray) -> np.ndarray:
        return self.columns.top(self._xy(xy))

    def bottom(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.columns.bottom(self._xy(xy))

    def region(self, points: np.ndarray) -> np.ndarray:
        return self.columns.region(points)

    @property
    def interface(self):
        inner = self.columns.interface
        return None if inner is None else (lambda xy: inner(self._xy(xy)))


def hole_site(inputs: HoleInputs, femur, options: HoleOptions = HoleOptions()) -> HoleSite:
    """The hole's geometry at the femur's drill site: the columns from the bone's surfaces when
    the femur carries them (:func:`femstudy.hole.femur.surface_columns`), else from its mesh;
    the local model's radius fitted to the bone; the stations' tips (:func:`station_tips`)."""
    from femstudy.meshing.landmarks import outer_faces

    require(options.stations >= 1, f"the hole needs at least one station, got {options.stations}")
    start = time.perf_counter()
    frame = HoleFrame.along(femur.site.entry_point, femur.site.direction)
    outer = outer_faces(femur.mesh, femur.frame)
    surface = getattr(femur, "surface", None)
    if surface is not None:
        reach = options.submodel_radius_mm + 4 * options.smoothing_mm + 1.0
        columns = surface_columns(surface, femur.mesh, outer, frame, options.depth_cap_mm, reach)
    else:
        columns = femur_columns(femur.mesh, outer, frame, options.depth_cap_mm)
    radius = fitting_radius(columns, options.submodel_radius_mm, inputs.drill.radius_mm + options.cut_margin_mm + 1.0)
    if radius < options.submodel_radius_mm:
        log.warning("hole model: radius %.1f mm instead of %.1f mm, the largest that stays on the bone around the "
                    "hole; measures farther from the hole than it allows are missing", radius, options.submodel_radius_mm)
        options = replace(options, submodel_radius_mm=radius)
    if options.smoothing_mm > 0:
        columns = smooth_columns(columns, options.submodel_radius_mm, options.smoothing_mm)
    axis_bottom, axis_free = columns.bottom(np.zeros((1, 2)))
    axis_bottom = float(axis_bottom[0]) if axis_free[0] else np.inf
    tips = station_tips(options, inputs.drilled_depth_mm, axis_bottom)
    if surface is not None:
        from femstudy.meshing.site_surface import local_axis

        axis, evidence = local_axis(surface, femur.frame.up)
    else:
        axis, evidence = np.asarray(femur.frame.up, float), {"axis": "femur long axis", "why": "no surface"}
    site = HoleSite(frame, columns, options, tips, axis_bottom, time.perf_counter() - start, axis, evidence)
    return site.turned(options.rotation_deg) if options.rotation_deg else site


def hole_stresses(inputs: HoleInputs, femur, system, unit_fields: np.ndarray, options: HoleOptions = HoleOptions(),
                  solver: str = "auto", keep: Path | None = None, site: HoleSite | None = None,
                  stations: tuple | None = None, scenarios: tuple = (),
                  locator: MeshLocator | None = None) -> HoleResult:
    """Stresses near the drilled hole at a few depth stations, driven by the global model.

    Parameters
    ----------
    inputs : HoleInputs
        Drill, materials, element order, clamped length, depth and the loads at each tip depth.
    femur : :class:`femstudy.meshing.FemurModel`
        The global femur (no hole): its mesh, frame, drill site and surfaces.
    system : :class:`femstudy.fe.FESystem`
        Assembled on ``femur.mesh``.
    unit_fields : (n_dofs, 2) ndarray
        Global displacements [mm] under a unit patch thrust [1 N] and torque [1 N·mm].
    options : HoleOptions
        Its refinement sets the local models' mesh; with ``site`` given its geometry options
        are the site's.
    solver : str
        Linear solver of the local models.
    keep : Path, optional
        Folder of kept solutions for the local models (:func:`femstudy.fe.factorize`) and of their
        sample points (:func:`femstudy.hole.measures.distance_samples`).
    site : HoleSite, optional
        The geometry (:func:`hole_site`) when already built, e.g. for another refinement.
    stations : tuple of int, optional
        Only these stations (negative numbers count from the deepest); default all.
    scenarios : tuple of HoleScenario
        Alternatives measured on the same meshes (:class:`HoleScenario`; ``HoleResult.scenarios``).
    locator : :class:`~femstudy.hole.probe.MeshLocator` of ``system``, to reuse one built before

    Returns
    -------
    HoleResult

    Examples
    --------
    >>> fields = fs.bc.expand(fs.factor.solve(patch.patterns[fs.bc.free]))   # doctest: +SKIP
    >>> result = hole_stresses(inputs, femur, system, fields)                 # doctest: +SKIP
    >>> result.headline().von_mises_MPa                                       # doctest: +SKIP
    """
    from femstudy.fe import assemble

    start = time.perf_counter()
    site = hole_site(inputs, femur, options) if site is None else site
    options = replace(site.options, refinement=options.refinement)
    frame, columns, tips = site.frame, site.columns, site.tips
    hole = hole_mesh(frame, inputs.drill.diameter_mm, inputs.drill.point_angle_deg, options.submodel_radius_mm, tips,
                     columns.top, columns.bottom, columns.region, Resolution(refinement=options.refinement),
                     columns.interface)
    mesh_seconds = time.perf_counter() - start
    log.info("hole model: %d stations (tips %s mm), refinement %.3g, column mesh %.1f s", len(tips),
             ", ".join(f"{t:.2f}" for t in tips), options.refinement, mesh_seconds)
    up, axis = np.asarray(femur.frame.up, float), np.asarray(site.bone_axis, float)
    heights = femur.mesh.points @ up
    static = tuple(float(x) for x in inputs.static_load)
    runs, measures = [], []
    global_locator = locator or MeshLocator(system)  # every station's cut nodes are found in the one femur mesh
    chosen = set(range(len(tips))) if stations is None else {k % len(tips) for k in stations}
    scenarios = tuple(scenarios)
    fields = np.hstack([unit_fields] + [s.unit_fields for s in scenarios if s.unit_fields is not None])
    field_of = 1 + np.cumsum([0] + [s.unit_fields is not None for s in scenarios])  # field set of each scenario's own
    tractions = list(dict.fromkeys([options.cone_traction] + [s.cone_traction for s in scenarios if s.cone_traction]))
    of_scenarios = {s.name: [] for s in scenarios}
    for k, tip in enumerate(tips):
        if k not in chosen:
            continue
        start = time.perf_counter()
        station = hole.at_station(k)
        local = assemble(station.mesh, inputs.materials, order=inputs.order, long_axis=axis)
        load = inputs.station_load(float(tip))
        t, F_cut, T_cut, F_evac, T_evac = (load.time_s, load.cutting_thrust_N, load.cutting_torque_Nmm,
                                           load.evacuation_thrust_N, load.evacuation_torque_Nmm)
        cut = cut_boundary(system, fields, local, station, locator=global_locator)
        patterns = np.hstack([hole_loads(local, station, growth_exponent=inputs.growth_exponent,
                                         cone_traction=traction).patterns for traction in tractions])
        samples = distance_samples(local, station, options.distances_mm, keep)
        excluded = _excluded(local, cut.dofs, heights, up, inputs.clamp_length_mm, options.cut_margin_mm)
        # (patch thrust, torque) on the cut faces and the 4 hole loads (HoleLoads.force order), per loading
        dynamic = np.array([F_cut + F_evac, T_cut + T_evac, F_cut, T_cut, T_evac, F_evac])
        static_loading = np.array([*static, *static, 0.0, 0.0])

        def responses(field: int, traction: str, loading: np.ndarray) -> np.ndarray:
            """Coefficients of the unit responses' columns for one field set, traction and loading."""
            c = np.zeros(fields.shape[1] + 4 * len(tractions))
            c[2 * field:2 * field + 2] = loading[:2]
            at = fields.shape[1] + 4 * tractions.index(traction)
            c[at:at + 4] = loading[2:]
            return c

        unit, factorisations = _unit_responses(local, cut, patterns, solver, keep)
        u = unit @ np.column_stack([responses(0, options.cone_traction, dynamic),
                                    responses(0, options.cone_traction, static_loading)])
        measures += _station_measures(local, station, u, options, axis, excluded, samples, LOADINGS)
        for materials in dict.fromkeys(s.materials for s in scenarios):  # one factorisation per materials
            group = [(i, s) for i, s in enumerate(scenarios) if s.materials is materials]
            if materials is not None:
                local = assemble(station.mesh, materials, order=inputs.order, long_axis=axis)
                unit, more = _unit_responses(local, cut, patterns, solver, keep)
                factorisations += more
            u = unit @ np.column_stack([responses(int(field_of[i]) if s.unit_fields is not None else 0,
                                                  s.cone_traction or options.cone_traction, dynamic)
                                        for i, s in group])
            for j, (_, s) in enumerate(group):
                held = excluded if s.clamp_length_mm is None else \
                    _excluded(local, cut.dofs, heights, up, s.clamp_length_mm, options.cut_margin_mm)
                of_scenarios[s.name] += _station_measures(local, station, u[:, j:j + 1], options, axis, held,
                                                          samples, ("dynamic",))
        seconds = time.perf_counter() - start
        runs.append(StationRun(k, float(tip), t, F_cut, T_cut, F_evac, T_evac, local.n_dofs, len(cut.dofs), seconds,
                               cut.moved_mm, factorisations))
        log.info("hole station %d (tip %.2f mm): %d DOFs%s, %.1f s", k, tip, local.n_dofs,
                 f", {len(scenarios)} alternatives" if scenarios else "", seconds)
    return HoleResult(options, tuple(runs), tuple(measures), static, mesh_seconds, site.axis_bottom_mm,
                      tuple(float(x) for x in axis), site.bone_axis_evidence,
                      {name: tuple(found) for name, found in of_scenarios.items()} if scenarios else None)


def _station_measures(local, station, u, options, axis, excluded, samples, loadings) -> list:
    """Every measure of one station's solution ``u`` (n_dofs, one column per loading)."""
    return (distance_measures(local, station, u, options.distances_mm, axis, loadings, samples)
            + exclusion_measures(local, station, u, options.exclusion_radii_mm, axis, excluded, loadings))


def _unit_responses(local, cut, patterns, solver, keep) -> tuple[np.ndarray, int]:
    """The local model's unit responses [mm] and the factorisations they took: the cut faces
    under each global field (``cut.values``' columns), and each unit hole load (``patterns``'
    columns) with the cut faces held. Any loading combines them, so kept solutions serve a study
    that changes only the loads; the factorisation is released on return, before the measures
    are taken."""
    n_cut, n_hole = cut.values.shape[1], patterns.shape[1]
    prescribed = factorize_prescribed(local, cut.dofs, solver, keep)
    unit = prescribed.solve(np.hstack([cut.values, np.zeros((len(cut.dofs), n_hole))]),
                            np.hstack([np.zeros((local.n_dofs, n_cut)), patterns]))
    prescribed.fs.factor.close()
    return unit, prescribed.fs.factor.factorisations


#: Azimuths and radial step [mm] of the probe for the largest local model that stays on the bone.
PROBE_AZIMUTHS = 96
PROBE_STEP_MM = 0.5


def fitting_radius(columns, requested_mm: float, least_mm: float) -> float:
    """The largest local-model radius [mm], at most ``requested_mm``, whose outer ring of columns
    all meet the bone's outer surface (at a narrow site, such as the femoral neck, an 8 mm disk
    reaches past the bone); a radius below ``least_mm`` leaves no room for the measures."""
    angles = np.linspace(0.0, 2 * np.pi, PROBE_AZIMUTHS, endpoint=False)
    rings = np.concatenate([f * np.column_stack([np.cos(angles), np.sin(angles)]) for f in (0.25, 0.5, 0.75, 1.0)])
    radius = requested_mm
    while radius >= least_mm:
        if np.all(columns.covers(radius * rings)):
            return radius
        radius -= PROBE_STEP_MM
    raise UserError(f"the bone around the drill site is too narrow for a local model of the hole: its outer surface "
                    f"does not surround the drill axis even {least_mm:.1f} mm from it (use loads.application = "
                    "\"surface_patch\" at this site)")


def _excluded(local, cut_dofs: np.ndarray, heights: np.ndarray, up: np.ndarray, clamp_mm: float,
              margin_mm: float) -> np.ndarray:
    """(n_tets, nq) True at quadrature points within ``margin_mm`` of a cut-face node or within
    the clamped length of either end of the femur (heights along ``up``)."""
    from scipy.spatial import cKDTree

    from femstudy.fe.post import quadrature_points

    points = quadrature_points(local)
    flat = points.reshape(-1, 3)
    near_cut = cKDTree(local.nodes[np.unique(cut_dofs // 3)]).query(flat, distance_upper_bound=margin_mm)[0] <= margin_mm
    h = flat @ up
    in_clamp = (h > heights.max() - clamp_mm) | (h < heights.min() + clamp_mm)
    return (near_cut | in_clamp).reshape(points.shape[:2])
