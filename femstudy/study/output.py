"""The files of a study's results folder: time series, figures, picture, fields, summary and report.

They are written into the folder being built (:func:`femstudy.atomic.atomic_folder`, opened by
:func:`femstudy.study.run.run_study`): :func:`write_files` possibly by a forked process
(:mod:`femstudy.lanes`), :func:`write_summary` last, by the study's own."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from femstudy.fe.post import nodal_average
from femstudy.jsonable import default
from femstudy.study import fields, figures, render, report
from femstudy.study.results import timeseries_csv



def _von_mises_vertices(system, vm_rows: np.ndarray, coordinates: np.ndarray) -> np.ndarray:
    """Vertex von Mises [MPa] of the field basis @ coordinates, from the projected stress rows."""
    vm = np.linalg.norm(vm_rows @ coordinates, axis=1)
    return nodal_average(system, vm.reshape(system.n_tets, -1))


def warp_factor(model, dynamic) -> float:
    """The displacement scale of the pictures: a round number from the dynamic peak deflection."""
    return render.nice_warp_factor(dynamic.peak("max_deflection_mm").value, float(model.frame.length_mm))


def write_files(folder: Path, case, model, system, basis, vm_rows, kept: dict, static_u, times, dynamic,
                static) -> list[str]:
    """Write timeseries.csv, the figures (loads, deflection and von Mises against time),
    femur.png (the deformed femur at the kept step nearest the dynamic peak deflection) and
    fields/*.pvd into ``folder``, as the case asks; return the figures' file names.

    ``basis`` (n_dofs, m) spans every kept field; ``vm_rows`` is the von Mises channel's
    projection of it; ``kept`` maps step indices to full displacement fields [mm]; ``static_u``
    is the static loading's displacement [mm]; ``dynamic`` and ``static`` the loadings' results.
    """
    (folder / "timeseries.csv").write_text(timeseries_csv([dynamic, static]))
    written = figures.write_figures(folder, case.name, [dynamic, static]) if case.output.figures else []
    picture = case.output.screenshot and kept
    base = fields.grid(system.nodes, system.cells, system.region, model.frame.up) if picture or case.output.fields \
        else None

    def with_solution(u):
        return fields.with_solution(base, u, _von_mises_vertices(system, vm_rows, basis.T @ u), system.cells)

    if picture:
        peak_step = int(np.searchsorted(times, dynamic.peak("max_deflection_mm").time_s))
        step = min(kept, key=lambda n: abs(n - peak_step))
        render.deformed_picture(folder / "femur.png", with_solution(kept[step]), model.site.entry_point,
                                model.site.direction, warp_factor(model, dynamic),
                                f"{case.name}: dynamic loading, t = {times[step]:.2f} s")
        written.append("femur.png")
    if case.output.fields:
        steps = sorted(n for n in kept if n % case.output.fields_every == 0 or n == len(times) - 1)
        fields.write_series(folder / "fields", "dynamic", [(float(times[n]), with_solution(kept[n])) for n in steps])
        fields.write_series(folder / "fields", "static", [(0.0, with_solution(static_u))])
    return written


def write_summary(folder: Path, result, model, figure_files: list[str]) -> None:
    """Write summary.json and report.md into ``folder``; ``figure_files`` names the figures
    there (:func:`write_files`)."""
    case, summary = result.case, result.summary
    summary["figures"] = {"warp_factor": warp_factor(model, result.dynamic), "files": figure_files,
                          "fields": ["fields/dynamic.pvd", "fields/static.pvd"] if case.output.fields else []}
    (folder / "summary.json").write_text(json.dumps(summary, indent=2, default=default))
    (folder / "report.md").write_text(report.run_report(summary))
