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
from typing import Callable

import numpy as np

from femstudy.drilling.drill import Drill
from femstudy.errors import UserError, require
from femstudy.materials import BoneMaterials
from femstudy.hole.coupling import cut_boundary
from femstudy.hole.dirichlet import factorize_prescribed
from femstudy.hole.femur import femur_columns, smooth_columns
from femstudy.hole.frame import HoleFrame
from femstudy.hole.loads import hole_loads
from femstudy.hole.measures import HoleMeasure, distance_measures, exclusion_measures
from femstudy.hole.mesh import Resolution, hole_mesh
from femstudy.hole.probe import MeshLocator

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
    """

    options: HoleOptions
    stations: tuple
    measures: tuple
    static_load: tuple
    mesh_seconds: float
    axis_bottom_mm: float

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
        """Failure margins (:mod:`femstudy.failure`: Tsai–Wu strength ratio for cortical bone,
        von Mises against the mean strength for cancellous bone; docs/failure.md): per loading, the
        smallest strength ratio over the stations at every distance from the hole and outside the
        quoted exclusion radius, with the station and point where it occurs."""
        out = {"basis": "hole", "criterion": "Tsai-Wu (cortical), von Mises / mean strength (cancellous)",
               "source": "femstudy/failure.py, docs/failure.md"}
        sets = [("distance", r) for r in self.options.distances_mm] + [("exclusion", self.options.exclusion_radius_mm)]
        for loading in LOADINGS:
            rows = []
            for kind, radius in sets:
                found = [m for m in self.measures if m.kind == kind and m.loading == loading
                         and abs(m.radius_mm - radius) < 1e-9 and np.isfinite(m.strength_ratio)]
                if found:
                    worst = min(found, key=lambda m: m.strength_ratio)
                    rows.append({"kind": kind, "radius_mm": float(radius), "strength_ratio": worst.strength_ratio,
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


def hole_stresses(inputs: HoleInputs, femur, system, unit_fields: np.ndarray, options: HoleOptions = HoleOptions(),
                  solver: str = "auto", keep: Path | None = None) -> HoleResult:
    """Stresses near the drilled hole at a few depth stations, driven by the global model.

    Parameters
    ----------
    inputs : HoleInputs
        Drill, materials, element order, clamped length, depth and the loads at each tip depth.
    femur : :class:`femstudy.meshing.FemurModel`
        The global femur (no hole): its mesh, frame and drill site.
    system : :class:`femstudy.fe.FESystem`
        Assembled on ``femur.mesh``.
    unit_fields : (n_dofs, 2) ndarray
        Global displacements [mm] under a unit patch thrust [1 N] and torque [1 N·mm].
    options : HoleOptions
    solver : str
        Linear solver of the local models.
    keep : Path, optional
        Folder of kept solutions for the local models (:func:`femstudy.fe.factorize`).

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
    from femstudy.meshing.landmarks import outer_faces

    require(options.stations >= 1, f"the hole needs at least one station, got {options.stations}")
    start = time.perf_counter()
    frame = HoleFrame.along(femur.site.entry_point, femur.site.direction)
    if options.rotation_deg:
        c, s = np.cos(np.radians(options.rotation_deg)), np.sin(np.radians(options.rotation_deg))
        frame = HoleFrame(frame.origin, frame.axis, c * frame.e1 + s * frame.e2, c * frame.e2 - s * frame.e1)
    columns = femur_columns(femur.mesh, outer_faces(femur.mesh, femur.frame), frame, options.depth_cap_mm)
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
    hole = hole_mesh(frame, inputs.drill.diameter_mm, inputs.drill.point_angle_deg, options.submodel_radius_mm, tips,
                     columns.top, columns.bottom, columns.region, Resolution(refinement=options.refinement),
                     columns.interface)
    mesh_seconds = time.perf_counter() - start
    log.info("hole model: %d stations (tips %s mm), column mesh %.1f s", len(tips),
             ", ".join(f"{t:.2f}" for t in tips), mesh_seconds)
    up = np.asarray(femur.frame.up, float)
    heights = femur.mesh.points @ up
    static = tuple(float(x) for x in inputs.static_load)
    runs, measures = [], []
    global_locator = MeshLocator(system)  # every station's cut nodes are found in the one femur mesh
    for k, tip in enumerate(tips):
        start = time.perf_counter()
        station = hole.at_station(k)
        local = assemble(station.mesh, inputs.materials, order=inputs.order, long_axis=up)
        load = inputs.station_load(float(tip))
        t, F_cut, T_cut, F_evac, T_evac = (load.time_s, load.cutting_thrust_N, load.cutting_torque_Nmm,
                                           load.evacuation_thrust_N, load.evacuation_torque_Nmm)
        cut = cut_boundary(system, unit_fields, local, station, locator=global_locator)
        patterns = hole_loads(local, station, growth_exponent=inputs.growth_exponent)
        unit, factorisations = _unit_responses(local, cut, patterns, solver, keep)
        loadings = np.array([[F_cut + F_evac, T_cut + T_evac, F_cut, T_cut, T_evac, F_evac],  # HoleLoads.force order
                             [*static, *static, 0.0, 0.0]]).T  # (patch thrust, torque, 4 hole loads) × 2 loadings
        u = unit @ loadings
        measures += distance_measures(local, station, u, options.distances_mm, up, LOADINGS)
        excluded = _excluded(local, cut.dofs, heights, up, inputs.clamp_length_mm, options.cut_margin_mm)
        measures += exclusion_measures(local, station, u, options.exclusion_radii_mm, up, excluded, LOADINGS)
        seconds = time.perf_counter() - start
        runs.append(StationRun(k, float(tip), t, F_cut, T_cut, F_evac, T_evac, local.n_dofs, len(cut.dofs), seconds,
                               cut.moved_mm, factorisations))
        log.info("hole station %d (tip %.2f mm): %d DOFs, %.1f s", k, tip, local.n_dofs, seconds)
    return HoleResult(options, tuple(runs), tuple(measures), static, mesh_seconds, axis_bottom)


def _unit_responses(local, cut, patterns, solver, keep) -> tuple[np.ndarray, int]:
    """The local model's unit responses [mm] and the factorisations they took: the cut faces
    under the global field of a unit patch thrust and torque, and each unit hole load with the
    cut faces held. Any loading combines them, so kept solutions serve a study that changes only
    the loads; the factorisation is released on return, before the measures are taken."""
    n_cut, n_hole = cut.values.shape[1], patterns.patterns.shape[1]
    prescribed = factorize_prescribed(local, cut.dofs, solver, keep)
    unit = prescribed.solve(np.hstack([cut.values, np.zeros((len(cut.dofs), n_hole))]),
                            np.hstack([np.zeros((local.n_dofs, n_cut)), patterns.patterns]))
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
