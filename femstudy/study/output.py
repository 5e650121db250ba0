"""The results folder of a study: tables, figures, fields and the report, written atomically."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.fe.post import nodal_average
from femstudy.jsonable import default
from femstudy.study import fields, figures, render, report
from femstudy.study.results import timeseries_csv

log = logging.getLogger(__name__)


def _von_mises_vertices(system, vm_rows: np.ndarray, coordinates: np.ndarray) -> np.ndarray:
    """Vertex von Mises [MPa] of the field basis @ coordinates, from the projected stress rows."""
    vm = np.linalg.norm(vm_rows @ coordinates, axis=1)
    return nodal_average(system, vm.reshape(system.n_tets, -1))


def write_results(out_dir: Path, result, model, system, basis, vm_rows, static_u, kept: dict, times) -> None:
    """Write timeseries.csv, summary.json, report.md, the figures, fields/*.pvd and femur.png.

    ``basis`` (n_dofs, m) spans every written field; ``vm_rows`` is the von Mises channel's
    projection of it; ``kept`` maps step indices to full displacement fields [mm].
    """
    case, summary = result.case, result.summary
    log.info("writing results to %s", out_dir)
    warp = render.nice_warp_factor(result.peak("max_deflection_mm").value, summary["mesh"]["length_mm"])
    summary["figures"] = {"warp_factor": warp, "files": []}

    def vertex_vm(u):
        return _von_mises_vertices(system, vm_rows, basis.T @ u)

    with atomic.atomic_folder(out_dir) as tmp:
        (tmp / "timeseries.csv").write_text(timeseries_csv([result.dynamic, result.static]))
        if case.output.figures:
            summary["figures"]["files"] = figures.write_figures(tmp, case.name, [result.dynamic, result.static])
        base = fields.grid(system.nodes, system.cells, system.region, model.frame.up)
        if case.output.fields:
            field_steps = sorted(n for n in kept if n % case.output.fields_every == 0 or n == len(times) - 1)
            frames = [(float(times[n]), fields.with_solution(base, kept[n], vertex_vm(kept[n]), system.cells))
                      for n in field_steps]
            fields.write_series(tmp / "fields", "dynamic", frames)
            static_grid = fields.with_solution(base, static_u, vertex_vm(static_u), system.cells)
            fields.write_series(tmp / "fields", "static", [(0.0, static_grid)])
        if case.output.screenshot and kept:
            peak_step = int(np.searchsorted(times, result.peak("max_deflection_mm").time_s))
            step = min(kept, key=lambda n: abs(n - peak_step))
            g = fields.with_solution(base, kept[step], vertex_vm(kept[step]), system.cells)
            render.deformed_picture(tmp / "femur.png", g, model.site.entry_point, model.site.direction, warp,
                                    f"{case.name}: dynamic loading, t = {times[step]:.2f} s")
            summary["figures"]["files"].append("femur.png")
        summary["figures"]["fields"] = ["fields/dynamic.pvd", "fields/static.pvd"] if case.output.fields else []
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2, default=default))
        (tmp / "report.md").write_text(report.run_report(summary))
