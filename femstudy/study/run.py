"""One study run: case → femur model → load histories → static and transient FE → results.

The results folder is built under a temporary name and renamed into place at the end
(:func:`femstudy.atomic.atomic_folder`), so an interrupted run never leaves a folder that
looks complete.
"""

from __future__ import annotations

import json
import platform
import time
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

import numpy as np

from femstudy import __version__, atomic
from femstudy.casefile import Case
from femstudy.console import Console
from femstudy.femur_model import REGION_NAMES
from femstudy.study import fields, figures, render, report
from femstudy.study.loading import case_loading
from femstudy.study.results import LoadingResult, comparison, timeseries_csv

PACKAGES = ("numpy", "scipy", "scikit-fem", "pytetwild", "pyvista", "meshio", "pypardiso")


def versions() -> dict:
    """Versions of Python, femstudy and the numerical packages used."""
    out = {"python": platform.python_version(), "femstudy": __version__}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def _loading_result(name, times, thrust, torque, rows, system) -> LoadingResult:
    """Collect per-step ``femstudy.fe.response`` dicts into a :class:`LoadingResult`."""
    def column(key):
        return np.array([r[key] for r in rows], float)

    region_codes = {v: k for k, v in REGION_NAMES.items()}
    return LoadingResult(
        name=name, time_s=np.asarray(times, float), thrust_N=np.asarray(thrust, float),
        torque_Nmm=np.asarray(torque, float),
        max_deflection_mm=column("max_deflection_mm"), max_deflection_point=column("max_deflection_at_mm"),
        drill_point_deflection_mm=column("drill_point_deflection_mm"),
        max_von_mises_MPa=column("max_von_mises_MPa"), max_von_mises_point=column("max_von_mises_at_mm"),
        max_von_mises_excl_MPa=column("max_von_mises_outside_MPa"),
        max_von_mises_excl_point=np.array([r["max_von_mises_outside_at_mm"] or [np.nan] * 3 for r in rows], float),
        region_max_von_mises_MPa={region_codes[name]: np.array([r["regions"][name]["max_von_mises_MPa"] for r in rows])
                                  for name in rows[0]["regions"]},
        strain_energy_mJ=column("strain_energy_mJ"))


def _field_steps(n_steps: int, every: int) -> list[int]:
    return sorted(set(range(0, n_steps, every)) | {n_steps - 1})


def run_case(case: Case, out_dir: Path, mesh_size_mm: float | None = None,
             console: Console | None = None) -> dict:
    """Run ``case`` and write its results folder; return the summary (also summary.json)."""
    from femstudy import fe
    from femstudy.meshing import build_femur_model

    console = console or Console()
    if mesh_size_mm is not None:  # so that summary.json echoes the size actually used
        case = case.model_copy(update={"mesh": case.mesh.model_copy(update={"size_mm": float(mesh_size_mm)})})
    clock = {"start": time.perf_counter()}
    console.progress(f"case '{case.name}': building or loading the femur mesh")
    model = build_femur_model(case, console=console)
    clock["mesh"] = time.perf_counter()

    loading = case_loading(case, model.site.cortical_thickness_mm)
    times = loading.times_s
    dyn = loading.dynamic
    console.progress(f"loads: dynamic peak {dyn.thrust_N.max():.1f} N / {dyn.torque_Nmm.max():.1f} N.mm, "
                     f"static {loading.static_thrust_N:.1f} N / {loading.static_torque_Nmm:.1f} N.mm, "
                     f"{len(times) - 1} steps of {case.time.step_s:g} s")

    system = fe.assemble(model.mesh, case.materials, order=case.mesh.order,
                         long_axis=model.frame.up, console=console)
    bc = fe.clamp(system, model.clamps)
    patch = fe.drill_patch(system, model.site, radius_mm=case.drill.diameter_mm / 2)
    clock["assembly"] = time.perf_counter()
    excl = case.analysis.exclusion_radius_mm

    console.progress("static Allotta loading (full-engagement thrust and torque)")
    u_static = fe.solve_static(system, bc, patch.force(loading.static_thrust_N, loading.static_torque_Nmm),
                               console=console)
    static_row = fe.response(system, u_static, patch, excl)
    static = _loading_result("static", times, np.full_like(times, loading.static_thrust_N),
                             np.full_like(times, loading.static_torque_Nmm), [static_row] * len(times), system)
    clock["static"] = time.perf_counter()

    keep = set(_field_steps(len(times), case.output.fields_every)) if case.output.fields else set()
    if case.output.screenshot:  # the picture shows the step of peak thrust (breakthrough)
        keep.add(int(np.argmax(dyn.thrust_N)))
    rows: list[dict] = []

    def observe(n, t, u):  # per-step response; the summary columns come from `rows`
        rows.append(fe.response(system, u, patch, excl))
        return {}

    amplitudes = np.column_stack([dyn.thrust_N, dyn.torque_Nmm])
    if case.analysis.transient:
        console.progress("dynamic loading: cutting + chip evacuation, Newmark average acceleration")
        hist = fe.solve_transient(system, bc, patch.patterns, amplitudes, times,
                                  damping=(case.analysis.rayleigh_alpha_per_s, case.analysis.rayleigh_beta_s),
                                  keep=keep, observe=observe, quasi_static=True, console=console)
        kept, linear_solver, amplification = hist.fields, hist.solver, hist.quasi_static
    else:
        console.progress("dynamic loading: cutting + chip evacuation, quasi-static (no inertia)")
        u_all = fe.solve_static(system, bc, patch.patterns @ amplitudes.T)
        for n, t in enumerate(times):
            observe(n, t, u_all[:, n])
        kept = {n: u_all[:, n] for n in keep}
        linear_solver, amplification = fe.static.stiffness_factor(system, bc).method, None
    dynamic = _loading_result("dynamic", times, dyn.thrust_N, dyn.torque_Nmm, rows, system)
    clock["dynamic"] = time.perf_counter()

    modal = {}
    if case.analysis.modes:
        console.progress(f"modal analysis: lowest {case.analysis.modes} modes")
        modes = fe.solve_modal(system, bc, k=case.analysis.modes, console=console)
        check = fe.step_check(float(modes.period_s[0]), case.time.step_s)
        modal = {"frequencies_Hz": [float(f) for f in modes.frequency_Hz],
                 "lowest_period_s": check["lowest_period_s"], "step_check": check["verdict"],
                 "step_resolves_lowest_mode": check["verdict"] == "resolved",
                 "dynamic_amplification": (amplification or {}).get("dynamic_amplification", 1.0)}
    clock["modal"] = time.perf_counter()

    summary = _summary(case, model, loading, system, patch, static, dynamic, modal, linear_solver, clock)
    _write(out_dir, case, model, system, summary, static, dynamic, u_static, kept, times, console)
    return summary


def _summary(case, model, loading, system, patch, static, dynamic, modal, linear_solver, clock) -> dict:
    cond = loading.conditions
    mu_f, mu_w = cond.friction
    site = model.site
    return {
        "femstudy_version": __version__, "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "versions": versions(),
        "case_file": str(case.source) if case.source else None,
        "case": case.model_dump(mode="json"),
        "mesh": {**{k: v for k, v in model.stats.items()}, "quality": model.quality,
                 "surface": case.geometry.surface, "length_mm": float(model.frame.length_mm)},
        "site": {"name": case.site.name, "entry_point_mm": [float(x) for x in site.entry_point],
                 "direction": [float(x) for x in site.direction],
                 "outward_normal": [float(x) for x in site.outward_normal],
                 "cortical_thickness_mm": float(site.cortical_thickness_mm),
                 "load_patch_radius_mm": case.drill.diameter_mm / 2},
        "loading": {"feed_mm_s": cond.feed_mm_s, "spindle_rpm": cond.spindle_rpm,
                    "feed_per_rev_mm": cond.feed_per_rev_mm, "bone_set": cond.bone.name,
                    "mu_f": mu_f, "mu_w": mu_w, "growth_exponent": cond.growth_exponent,
                    "depth_mm": loading.depth_mm, "static_thrust_N": loading.static_thrust_N,
                    "static_torque_Nmm": loading.static_torque_Nmm,
                    "peak_thrust_N": float(dynamic.thrust_N.max()), "peak_torque_Nmm": float(dynamic.torque_Nmm.max()),
                    "breakthrough_s": cond.phase_times()["breakthrough"]},
        "solver": {"element_order": system.order, "dofs": system.n_dofs, "linear_solver": linear_solver,
                   "assembly": system.timings},
        "modal": modal,
        "results": comparison(dynamic, static),
        "margins": {"dynamic": dynamic.margins(), "static": static.margins()},
        "timings": {"mesh_s": clock["mesh"] - clock["start"], "assembly_s": clock["assembly"] - clock["mesh"],
                    "static_s": clock["static"] - clock["assembly"], "dynamic_s": clock["dynamic"] - clock["static"],
                    "modal_s": clock["modal"] - clock["dynamic"], "total_s": time.perf_counter() - clock["start"]},
    }


def _write(out_dir, case, model, system, summary, static, dynamic, u_static, kept, times, console) -> None:
    from femstudy import fe

    console.progress(f"writing results to {out_dir}")
    warp = render.nice_warp_factor(summary["results"]["max_deflection_mm"]["dynamic"]["value"],
                                   summary["mesh"]["length_mm"])
    summary["figures"] = {"warp_factor": warp}
    with atomic.atomic_folder(out_dir) as tmp:
        (tmp / "timeseries.csv").write_text(timeseries_csv([dynamic, static]))
        if case.output.figures:
            summary["figures"]["files"] = figures.write_figures(tmp, case.name, [dynamic, static])
        base = fields.grid(system.nodes, system.cells, system.region, model.frame.up)
        if case.output.fields:
            field_steps = set(_field_steps(len(times), case.output.fields_every))
            frames = [(float(times[n]), fields.with_solution(base, u, fe.von_mises_nodal(system, u), system.cells))
                      for n, u in sorted(kept.items()) if n in field_steps]
            fields.write_series(tmp / "fields", "dynamic", frames)
            static_grid = fields.with_solution(base, u_static, fe.von_mises_nodal(system, u_static), system.cells)
            fields.write_series(tmp / "fields", "static", [(0.0, static_grid)])
        if case.output.screenshot and kept:
            peak_step = int(np.argmax(dynamic.max_deflection_mm))
            step = min(kept, key=lambda n: abs(n - peak_step))
            g = fields.with_solution(base, kept[step], fe.von_mises_nodal(system, kept[step]), system.cells)
            render.deformed_picture(tmp / "femur.png", g, model.site.entry_point, model.site.direction, warp,
                                    f"{case.name}: dynamic loading, t = {times[step]:.2f} s")
            summary["figures"].setdefault("files", []).append("femur.png")
        summary["figures"]["fields"] = ["fields/dynamic.pvd", "fields/static.pvd"] if case.output.fields else []
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2, default=_json_default))
        (tmp / "report.md").write_text(report.run_report(summary))


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")
