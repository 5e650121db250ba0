"""The files of a study's results folder: time series, figures, picture, fields, summary and report.

They are written into the folder being built (:func:`femstudy.atomic.atomic_folder`, opened by
:func:`femstudy.study.run.run_study`): :func:`write_plots` and :func:`write_views` by whatever
executor the study was given (:mod:`femstudy.execution`; side by side when it forks),
:func:`write_summary` last, by the study itself."""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import numpy as np

from femstudy.fe.post import nodal_average
from femstudy.jsonable import default
from femstudy.study import fields, figures, render, report
from femstudy.study.results import timeseries_csv
from femstudy.study.study_result import Figures


#: Fields whose vertex von Mises come from one pass over the projected stress rows (the pass's
#: product holds rows × components × this many values: 50 MB at 8 mm).
FIELDS_PER_PASS = 8


def _von_mises_vertices(system, vm_rows: np.ndarray, coordinates: np.ndarray) -> np.ndarray:
    """Vertex von Mises [MPa] of the fields basis @ coordinates (m, k), one column each, from the
    projected stress rows, :data:`FIELDS_PER_PASS` fields per pass over them."""
    passes = []
    for start in range(0, coordinates.shape[1], FIELDS_PER_PASS):
        chunk = coordinates[:, start:start + FIELDS_PER_PASS]
        vm = np.linalg.norm(vm_rows @ chunk, axis=1)
        passes.append(nodal_average(system, vm.reshape(system.n_tets, -1, chunk.shape[1])))
    return np.hstack(passes)


def warp_factor(model, dynamic) -> float:
    """The displacement scale of the pictures: a round number from the dynamic peak deflection."""
    return render.nice_warp_factor(dynamic.peak("max_deflection_mm").value, float(model.frame.length_mm))


def write_plots(folder: Path, model, step) -> tuple[str, ...]:
    """Write timeseries.csv and, as the case asks, the figures (loads, deflection and von Mises
    against time) into ``folder``; return the figures' file names.

    ``model`` is the study's :class:`~femstudy.study.global_model.GlobalModel` and ``step`` its
    :class:`~femstudy.study.run.ThesisStep` (the loadings' results)."""
    results = [step.dynamic, step.static]
    (folder / "timeseries.csv").write_text(timeseries_csv(results))
    return tuple(figures.write_figures(folder, model.case.name, results)) if model.case.output.figures else ()


def write_views(folder: Path, model, step, times) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Write, as the case asks, femur.png (the deformed femur at the kept step nearest the
    dynamic peak deflection) and fields/*.pvd into ``folder``; return (pictures, fields).

    ``step`` is the study's :class:`~femstudy.study.run.ThesisStep` (the basis that spans every
    kept field, its von Mises projection, the kept fields and the static field [mm]) and
    ``times`` the case's time grid [s]. Its own part of the study's executor, beside
    :func:`write_plots`: the two draw with different libraries (pyvista and VTK, matplotlib)
    and take about as long as each other."""
    case, femur, system = model.case, model.femur, model.system
    dynamic, kept = step.dynamic, step.fields
    picture = case.output.screenshot and kept
    if not (picture or case.output.fields):
        return (), ()
    base = fields.grid(system.nodes, system.cells, system.region, femur.frame.up)
    peak_step = int(np.searchsorted(times, dynamic.peak("max_deflection_mm").time_s))
    pictured_step = min(kept, key=lambda k: abs(k - peak_step)) if picture else None
    steps = sorted(k for k in kept if k % case.output.fields_every == 0 or k == len(times) - 1) \
        if case.output.fields else []
    # every drawn field's vertex von Mises at once: "static" and the steps
    drawn = {"static": step.static_u} if case.output.fields else {}
    drawn.update({k: kept[k] for k in steps + ([pictured_step] if picture else [])})
    vm = _von_mises_vertices(system, step.von_mises_rows, step.basis.T @ np.column_stack(list(drawn.values())))
    column = {key: j for j, key in enumerate(drawn)}

    def with_solution(key):
        return fields.with_solution(base, drawn[key], vm[:, column[key]], system.cells)

    pictures = ()
    if picture:
        render.deformed_picture(folder / "femur.png", with_solution(pictured_step), femur.site.entry_point,
                                femur.site.direction, warp_factor(femur, dynamic),
                                f"{case.name}: dynamic loading, t = {times[pictured_step]:.2f} s")
        pictures = ("femur.png",)
    written_fields = ()
    if case.output.fields:
        fields.write_series(folder / "fields", "dynamic", [(float(times[k]), with_solution(k)) for k in steps])
        fields.write_series(folder / "fields", "static", [(0.0, with_solution("static"))])
        written_fields = ("fields/dynamic.pvd", "fields/static.pvd")
    return pictures, written_fields


def start_file_parts(executor, folder: Path, model, times) -> tuple:
    """Start :func:`write_plots` and (when the case asks for a picture or fields)
    :func:`write_views` on ``executor`` (:mod:`femstudy.execution`) before the step they draw
    exists: each is given it later (``give(step)``), and a forking executor meanwhile imports
    the part's plotting library in its process (matplotlib, pyvista)."""
    from femstudy.plotting import pyplot

    parts = (executor.start_given("figures", partial(write_plots, folder, model), warm=pyplot),)
    if model.case.output.screenshot or model.case.output.fields:
        parts += (executor.start_given("picture and fields", partial(write_views, folder, model, times=times),
                                       warm=render.start_offscreen),)
    return parts


def pictured(model, step, plots: tuple[str, ...], views: tuple[tuple[str, ...], tuple[str, ...]] = ((), ())) -> Figures:
    """What :func:`write_plots` and :func:`write_views` (when it ran) wrote, with the pictures'
    warp factor."""
    pictures, written_fields = views
    return Figures(warp_factor(model.femur, step.dynamic), plots + pictures, written_fields)


def write_summary(folder: Path, result) -> None:
    """Write summary.json and report.md of ``result`` (:class:`~femstudy.study.study_result.StudyResult`)
    into ``folder``."""
    summary = result.to_json()
    (folder / "summary.json").write_text(json.dumps(summary, indent=2, default=default))
    (folder / "report.md").write_text(report.run_report(summary))
