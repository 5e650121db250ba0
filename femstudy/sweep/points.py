"""What one sweep point computes.

- ``mesh`` points (mesh convergence): the femur meshed at one size, element order and
  refinement, loaded *statically* by the peak of the dynamic drilling load (the response is
  quasi-static, see docs/solver.md, so the peak of the transient equals this static
  solution to within the dynamic amplification). Returns mesh statistics, the response
  quantities and the mesh/solve times.
- ``study`` points (parameter sweeps): the full study (`femstudy run`) of the case with the
  point's overrides, into its own results folder; returns the headline numbers.

The case travels as its TOML text and path, which pickle to any process or Dask worker,
with the client's mesh-cache folder: the client meshes every point first, and workers read
those meshes instead of running TetWild themselves. TetWild is not deterministic, so this is
what makes a Dask run's numbers identical to a local run's; on a cluster the cache folder
must therefore be on a file system the workers share (or be a path they can all read).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from femstudy.casefile import parse_case, with_overrides
from femstudy.sweep.execute import Point


def _case(point: Point, case_text: str, case_source: str):
    return with_overrides(parse_case(case_text, Path(case_source)), point.overrides)


def evaluate(point: Point, case_text: str, case_source: str, runs_folder: str | None = None,
             mesh_cache: str | None = None) -> dict:
    """Evaluate a point (picklable entry point for the process pool and Dask); meshes come
    from ``mesh_cache`` when given."""
    if mesh_cache:
        os.environ["FEMSTUDY_CACHE"] = mesh_cache
    case = _case(point, case_text, case_source)
    if point.kind == "mesh":
        return mesh_point(case)
    return study_point(case, Path(runs_folder) / point.id)


def peak_load(case, cortical_thickness_mm: float) -> tuple[float, float, float]:
    """(time [s], thrust [N], torque [N·mm]) of the dynamic load at its peak thrust."""
    from femstudy.study.loading import case_loading

    dyn = case_loading(case, cortical_thickness_mm).dynamic
    k = int(np.argmax(dyn.thrust_N))
    return float(dyn.time_s[k]), float(dyn.thrust_N[k]), float(dyn.torque_Nmm[k])


def mesh_point(case) -> dict:
    """Mesh, assemble and solve statically under the peak dynamic load."""
    from femstudy import fe
    from femstudy.meshing import build_femur_model

    start = time.perf_counter()
    model = build_femur_model(case)
    meshed = time.perf_counter()
    t_peak, thrust, torque = peak_load(case, model.site.cortical_thickness_mm)
    system = fe.assemble(model.mesh, case.materials, order=case.mesh.order, long_axis=model.frame.up)
    bc = fe.clamp(system, model.clamps)
    patch = fe.drill_patch(system, model.site, radius_mm=case.drill.diameter_mm / 2)
    assembled = time.perf_counter()
    u = fe.solve_static(system, bc, patch.force(thrust, torque))
    solved = time.perf_counter()
    r = fe.response(system, u, patch, case.analysis.exclusion_radius_mm)
    volume = float(model.stats["tet_volume_mm3"])
    return {
        "size_mm": case.mesh.size_mm, "order": case.mesh.order, "refine": case.mesh.refine,
        "site_size_mm": case.mesh.site_size_mm if case.mesh.refine == "site" else None,
        "envelope": case.mesh.envelope,
        "nodes": len(system.nodes), "elements": system.n_tets, "dofs": system.n_dofs,
        "h_rep_mm": (volume / system.n_tets) ** (1 / 3),
        "load_time_s": t_peak, "thrust_N": thrust, "torque_Nmm": torque,
        "max_deflection_mm": r["max_deflection_mm"], "drill_point_deflection_mm": r["drill_point_deflection_mm"],
        "max_von_mises_MPa": r["max_von_mises_MPa"], "max_von_mises_excl_MPa": r["max_von_mises_outside_MPa"],
        "mesh_s": meshed - start, "tetwild_s": model.stats.get("tetwild_seconds"),
        "mesh_cache_hit": bool(model.stats.get("cache_hit")),
        "assembly_s": assembled - meshed, "solve_s": solved - assembled, "solver": fe.static.stiffness_factor(system, bc).method,
    }


def study_point(case, folder: Path) -> dict:
    """The full study of one case into ``folder``; the headline numbers."""
    from femstudy.console import Console
    from femstudy.study.run import run_case

    summary = run_case(case, folder, console=Console(quiet=True))
    res = summary["results"]
    out = {"results_folder": str(folder), "dofs": summary["solver"]["dofs"],
           "mu_f": summary["loading"]["mu_f"], "mu_w": summary["loading"]["mu_w"],
           "peak_thrust_N": summary["loading"]["peak_thrust_N"], "peak_torque_Nmm": summary["loading"]["peak_torque_Nmm"],
           "total_s": summary["timings"]["total_s"]}
    for quantity in ("max_deflection_mm", "max_von_mises_MPa", "max_von_mises_excl_MPa"):
        out[f"{quantity}_dynamic"] = res[quantity]["dynamic"]["value"]
        out[f"{quantity}_static"] = res[quantity]["static"]["value"]
        out[f"{quantity}_ratio"] = res[quantity]["ratio_dynamic_to_static"]
    return out


def estimated_dofs(n_vertices: int, n_tets: int, order: int) -> int:
    """DOFs of a tet mesh: 3 per vertex, plus 3 per edge for P2 (edges ≈ vertices + tets)."""
    return 3 * (n_vertices if order == 1 else 2 * n_vertices + n_tets)


def estimated_memory_bytes(dofs: int) -> float:
    """Peak memory of assembling and factorising a P2 elasticity system of ``dofs`` unknowns.

    Direct-solver fill grows like n^(4/3) on 3-D meshes; the constant is calibrated on the
    measurements in docs/solver.md (about 1.7 GB at 100k DOFs).
    """
    return 366.0 * dofs ** (4 / 3) + 0.5e9
