"""What one sweep point computes.

- ``mesh`` points (mesh convergence): the femur meshed at one size, element order and
  refinement, loaded *statically* by the peak of the dynamic drilling load (the response is
  quasi-static, see docs/solver.md, so the peak of the transient equals this static
  solution to within the dynamic amplification). Returns mesh statistics, the response
  quantities and the mesh/solve times.
- ``study`` points (parameter sweeps): the full study (`femstudy run`) of the case with the
  point's overrides, into its own results folder; returns the headline numbers.

The case travels as its TOML text and path (:class:`Context`), which pickle to any process
or Dask worker, with the client's mesh-cache folder: the client meshes every point first,
and workers read those meshes instead of running TetWild themselves. TetWild is not deterministic, so this is
what makes a Dask run's numbers identical to a local run's; on a cluster the cache folder
must therefore be on a file system the workers share (or be a path they can all read).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femstudy.casefile import parse_case, with_overrides
from femstudy.sweeps.execute import Point


@dataclass(frozen=True)
class Context:
    """What every point needs besides its overrides, as plain picklable values: the case's
    TOML text and path, the parameter sweep's runs folder, the mesh cache, the linear solver
    and the bone-set folder."""

    case_text: str
    case_source: str
    runs_folder: str | None
    cache_dir: str
    solver: str = "auto"
    bones_dir: str | None = None


def evaluate(point: Point, context: Context) -> dict:
    """Evaluate a point (picklable entry point for the process pool and Dask)."""
    case = with_overrides(parse_case(context.case_text, Path(context.case_source)), point.overrides)
    if point.kind == "mesh":
        return mesh_point(case, Path(context.cache_dir), context.solver)
    return study_point(case, Path(context.runs_folder) / point.id, context)


def peak_load(loading) -> tuple[float, float, float]:
    """(time [s], thrust [N], torque [N·mm]) of the dynamic load (of a
    :class:`~femstudy.study.loading.CaseLoading`) at its peak thrust."""
    dyn = loading.dynamic
    k = int(np.argmax(dyn.thrust_N))
    return float(dyn.time_s[k]), float(dyn.thrust_N[k]), float(dyn.torque_Nmm[k])


def mesh_point(case, cache_dir: Path, solver: str = "auto") -> dict:
    """Mesh, assemble and solve statically under the peak dynamic load."""
    from femstudy import fe
    from femstudy.study.global_model import prepare
    from femstudy.study.loading import case_loading

    start = time.perf_counter()
    model = prepare(case, cache_dir)
    meshed = start + model.mesh_s
    femur, system, patch = model.femur, model.system, model.patch
    loading = case_loading(case, femur.site.cortical_thickness_mm)
    t_peak, thrust, torque = peak_load(loading)
    fs = model.factorize(solver)
    assembled = time.perf_counter()
    u = fe.solve_static(fs, patch.force(thrust, torque))
    solved = time.perf_counter()
    recorder = fe.StepRecorder(model.channels, 1)
    recorder.step(0, u)
    r = recorder.history()
    volume = float(femur.stats["tet_volume_mm3"])
    hole = hole_quantities(model, fs, loading, solver) if case.loads.application == "hole" else {}
    return {**hole,
        "size_mm": case.mesh.size_mm, "order": case.mesh.order, "refine": case.mesh.refine,
        "site_size_mm": case.mesh.site_size_mm if case.mesh.refine == "site" else None,
        "envelope": case.mesh.envelope,
        "nodes": len(system.nodes), "elements": system.n_tets, "dofs": system.n_dofs,
        "h_rep_mm": (volume / system.n_tets) ** (1 / 3),
        "load_time_s": t_peak, "thrust_N": thrust, "torque_Nmm": torque,
        "max_deflection_mm": r["deflection"].peak, "drill_point_deflection_mm": r["drill_point"].peak,
        "max_von_mises_MPa": r["von_mises"].peak, "max_von_mises_excl_MPa": r["von_mises/outside"].peak,
        "mesh_s": meshed - start, "tetwild_s": femur.stats.get("tetwild_seconds"),
        "mesh_cache_hit": bool(femur.stats.get("cache_hit")),
        "assembly_s": assembled - meshed, "solve_s": solved - assembled, "solver": fs.method,
    }


def hole_quantities(model, fs, loading, solver: str = "auto") -> dict:
    """The hole model's element size, largest dynamic von Mises stresses at each distance from
    the hole wall and beyond the quoted exclusion radius (femstudy.hole.study), and its time;
    ``model`` a :class:`~femstudy.study.global_model.GlobalModel`, ``fs`` its factorisation."""
    from femstudy.hole.study import hole_stresses

    case = model.case
    start = time.perf_counter()
    fields = fs.bc.expand(fs.factor.solve(model.patch.patterns[fs.bc.free]))
    options = case.loads.hole_options()
    inputs = loading.hole_inputs(case.materials.to_fe(), case.mesh.order, case.clamps.length_mm)
    hole = hole_stresses(inputs, model.femur, model.system, fields, options, solver)
    out = {"hole_h_mm": hole.wall_element_mm, "hole_s": time.perf_counter() - start,
           "hole_von_mises_excl_MPa": hole.worst("exclusion", options.exclusion_radius_mm).von_mises_MPa}
    for distance in options.distances_mm:
        out[f"hole_von_mises_{distance:g}mm_MPa"] = hole.worst("distance", distance).von_mises_MPa
    return out


def study_point(case, folder: Path, context: Context) -> dict:
    """The full study of one case into ``folder``; the headline numbers."""
    from femstudy.study.run import run_study

    # a sweep runs its points side by side (processes, Dask workers): a point runs its parts in its own process
    result = run_study(case, folder, cache_dir=Path(context.cache_dir), solver=context.solver,
                       bones_dir=context.bones_dir and Path(context.bones_dir))
    mu_f, mu_w = result.loading.conditions.friction
    dyn = result.loading.dynamic
    out = {"results_folder": str(folder), "dofs": result.solver.dofs, "mu_f": mu_f, "mu_w": mu_w,
           "peak_thrust_N": float(dyn.thrust_N.max()), "peak_torque_Nmm": float(dyn.torque_Nmm.max()),
           "total_s": result.timings.total_s}
    for quantity in ("max_deflection_mm", "max_von_mises_MPa", "max_von_mises_excl_MPa"):
        d, s = result.peak(quantity).value, result.peak(quantity, "static").value
        out[f"{quantity}_dynamic"], out[f"{quantity}_static"] = d, s
        out[f"{quantity}_ratio"] = d / s if s > 0 else None
    return out


def estimated_dofs(n_vertices: int, n_tets: int, order: int) -> int:
    """DOFs of a tet mesh: 3 per vertex, plus 3 per edge for P2 (edges ≈ vertices + tets)."""
    return 3 * (n_vertices if order == 1 else 2 * n_vertices + n_tets)
