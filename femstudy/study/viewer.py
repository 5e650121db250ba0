"""Interactive and off-screen viewing of a results folder (fields/*.pvd + summary.json)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from femstudy.errors import require
from femstudy.study.render import deformed_picture, nice_warp_factor

SCALAR_TITLES = {"von_mises_MPa": "von Mises [MPa]", "displacement_magnitude_mm": "displacement [mm]",
                 "region": "region (1 cortical, 2/3 cancellous)"}


log = logging.getLogger(__name__)


def _read(results: Path, loading: str):
    summary_path = results / "summary.json"
    require(summary_path.is_file(), f"{results} is not a femstudy results folder (no summary.json)")
    summary = json.loads(summary_path.read_text())
    pvd = results / "fields" / f"{loading}.pvd"
    require(pvd.is_file(), f"{results} has no {loading} fields (run with [output] fields = true)")
    import pyvista as pv

    reader = pv.get_reader(str(pvd))
    require(len(reader.time_values) > 0, f"{pvd} lists no time steps")
    return summary, reader


def _frame(reader, time_s: float):
    times = np.asarray(reader.time_values)
    k = int(np.argmin(np.abs(times - time_s)))
    reader.set_active_time_value(times[k])
    grid = reader.read()[0]
    grid.point_data["displacement_magnitude_mm"] = np.linalg.norm(grid.point_data["displacement_mm"], axis=1)
    return grid, float(times[k])


def view(results: Path, loading: str = "dynamic", time_s: float | None = None, field: str = "von_mises_MPa",
         warp: float | None = None, screenshot: Path | None = None, interactive: bool = True) -> Path | None:
    """Show one loading of a results folder in a window, or write ``screenshot`` (PNG) when
    asked or when ``interactive`` is false (no display); returns the picture written."""
    summary, reader = _read(Path(results), loading)
    site = summary["site"]
    peak = summary["results"]["max_deflection_mm"][loading]
    warp = warp if warp is not None else summary.get("figures", {}).get("warp_factor") or nice_warp_factor(
        peak["value"], summary["mesh"]["length_mm"])
    if time_s is None:
        time_s = peak["time_s"]
    title = f"{summary['case']['name']}: {loading} loading"
    if screenshot is None and not interactive:
        screenshot = Path(results) / f"view-{loading}-{field}.png"
        log.info("no display: writing %s", screenshot)
    if screenshot is not None:
        grid, shown = _frame(reader, time_s)
        if field == "region":
            grid = grid.cell_data_to_point_data(pass_cell_data=True)
        deformed_picture(screenshot, grid, site["entry_point_mm"], site["direction"], warp,
                         f"{title}, t = {shown:.2f} s", scalars=field, scalar_title=SCALAR_TITLES[field])
        return screenshot
    _interactive(reader, site, warp, title, field)
    return None


def _interactive(reader, site, warp, title, field):  # pragma: no cover - needs a display
    import pyvista as pv

    times = list(reader.time_values)
    plotter = pv.Plotter(title=title)
    state = {}

    def show(value):
        grid, shown = _frame(reader, value)
        if field == "region":
            grid = grid.cell_data_to_point_data(pass_cell_data=True)
        surface = grid.extract_surface(algorithm="dataset_surface").warp_by_vector("displacement_mm", factor=warp)
        if "actor" in state:
            plotter.remove_actor(state["actor"])
        state["actor"] = plotter.add_mesh(surface, scalars=field, cmap="turbo",
                                          scalar_bar_args={"title": SCALAR_TITLES[field]})
        plotter.add_text(f"{title}, t = {shown:.2f} s, warp x{warp:g}", name="title", font_size=10)

    if len(times) > 1:
        plotter.add_slider_widget(show, [times[0], times[-1]], value=times[-1], title="time [s]")
    else:
        show(times[0])
    plotter.add_mesh(pv.Sphere(radius=2.0, center=site["entry_point_mm"]), color="black")
    plotter.show()
