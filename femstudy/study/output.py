"""The files of a study's results folder: time series, figures, picture, fields, summary and report.

They are written into the folder being built (:func:`femstudy.atomic.atomic_folder`, opened by
:func:`femstudy.study.run.run_study`): :func:`write_files` by whatever executor the study was
given (:mod:`femstudy.execution`), :func:`write_summary` last, by the study itself."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from femstudy.fe.post import nodal_average
from femstudy.jsonable import default
from femstudy.study import fields, figures, render, report
from femstudy.study.results import timeseries_csv
from femstudy.study.study_result import Figures


def _von_mises_vertices(system, vm_rows: np.ndarray, coordinates: np.ndarray) -> np.ndarray:
    """Vertex von Mises [MPa] of the field basis @ coordinates, from the projected stress rows."""
    vm = np.linalg.norm(vm_rows @ coordinates, axis=1)
    return nodal_average(system, vm.reshape(system.n_tets, -1))


def warp_factor(model, dynamic) -> float:
    """The displacement scale of the pictures: a round number from the dynamic peak deflection."""
    return render.nice_warp_factor(dynamic.peak("max_deflection_mm").value, float(model.frame.length_mm))


def write_files(folder: Path, model, step, times) -> Figures:
    """Write timeseries.csv, the figures (loads, deflection and von Mises against time),
    femur.png (the deformed femur at the kept step nearest the dynamic peak deflection) and
    fields/*.pvd into ``folder``, as the case asks; return what was pictured.

    ``model`` is the study's :class:`~femstudy.study.global_model.GlobalModel`, ``step`` its
    :class:`~femstudy.study.run.ThesisStep` (the loadings' results, the basis that spans every
    kept field, its von Mises projection, the kept fields and the static field [mm]) and
    ``times`` the case's time grid [s].
    """
    case, femur, system = model.case, model.femur, model.system
    dynamic, static, kept = step.dynamic, step.static, step.fields
    (folder / "timeseries.csv").write_text(timeseries_csv([dynamic, static]))
    written = figures.write_figures(folder, case.name, [dynamic, static]) if case.output.figures else []
    picture = case.output.screenshot and kept
    base = fields.grid(system.nodes, system.cells, system.region, femur.frame.up) if picture or case.output.fields \
        else None

    def with_solution(u):
        return fields.with_solution(base, u, _von_mises_vertices(system, step.von_mises_rows, step.basis.T @ u),
                                    system.cells)

    if picture:
        peak_step = int(np.searchsorted(times, dynamic.peak("max_deflection_mm").time_s))
        n = min(kept, key=lambda k: abs(k - peak_step))
        render.deformed_picture(folder / "femur.png", with_solution(kept[n]), femur.site.entry_point,
                                femur.site.direction, warp_factor(femur, dynamic),
                                f"{case.name}: dynamic loading, t = {times[n]:.2f} s")
        written.append("femur.png")
    written_fields = ()
    if case.output.fields:
        steps = sorted(k for k in kept if k % case.output.fields_every == 0 or k == len(times) - 1)
        fields.write_series(folder / "fields", "dynamic", [(float(times[k]), with_solution(kept[k])) for k in steps])
        fields.write_series(folder / "fields", "static", [(0.0, with_solution(step.static_u))])
        written_fields = ("fields/dynamic.pvd", "fields/static.pvd")
    return Figures(warp_factor(femur, dynamic), tuple(written), written_fields)


def write_summary(folder: Path, result) -> None:
    """Write summary.json and report.md of ``result`` (:class:`~femstudy.study.study_result.StudyResult`)
    into ``folder``."""
    summary = result.to_json()
    (folder / "summary.json").write_text(json.dumps(summary, indent=2, default=default))
    (folder / "report.md").write_text(report.run_report(summary))
