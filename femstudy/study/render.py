"""Off-screen PyVista pictures of a solved femur: deformed shape coloured by von Mises."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from femstudy import atomic


def nice_warp_factor(max_displacement_mm: float, length_mm: float, share: float = 0.04) -> float:
    """A 1-2-5 warp factor that draws the largest displacement as about ``share`` of the length."""
    if max_displacement_mm <= 0:
        return 1.0
    raw = share * length_mm / max_displacement_mm
    exponent = math.floor(math.log10(raw))
    mantissa = raw / 10 ** exponent
    step = 1 if mantissa < 2 else 2 if mantissa < 5 else 5
    return float(step * 10 ** exponent)


def start_offscreen():
    """Import pyvista, its plotting part included, configured for off-screen rendering (what a
    study's picture lane does while it waits for its field: femstudy.lanes).

    Without a display VTK first tries X, logs a warning and falls back to EGL/OSMesa;
    only VTK's errors are let through to stderr.
    """
    from vtkmodules.vtkCommonCore import vtkLogger

    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    import pyvista as pv
    import pyvista.plotting  # noqa: F401  (0.25 s: imported here, not on the first Plotter)

    pv.OFF_SCREEN = True
    return pv


def deformed_picture(path: Path, grid, site_point, site_direction, warp: float, title: str,
                     scalars: str = "von_mises_MPa", scalar_title: str = "von Mises [MPa]",
                     cap_percentile: float = 99.0, window=(1000, 1300)) -> None:
    """Render ``grid`` (a pyvista UnstructuredGrid with point vector ``displacement_mm`` and
    ``scalars``) warped by ``warp``, seen from the side so that the deflection along the drill
    axis shows in profile, over the undeformed outline, with an arrow for the drill; save a PNG.

    The colour scale is capped at the ``cap_percentile`` of the surface values, so that the
    local peak under the load patch does not leave the rest of the bone one colour; the picture
    quotes no value of that peak (it grows under mesh refinement, docs/convergence.md).
    """
    pv = start_offscreen()
    undeformed = grid.extract_surface(algorithm="dataset_surface")
    surface = undeformed.warp_by_vector("displacement_mm", factor=warp)
    values = np.asarray(surface.point_data[scalars], float)
    clim = [float(values.min()), float(max(np.percentile(values, cap_percentile), values.min() + 1e-12))]
    capped = clim[1] < values.max()
    site_point = np.asarray(site_point, float)
    direction = np.asarray(site_direction, float) / np.linalg.norm(site_direction)
    axis = np.asarray(grid.field_data["long_axis"]) if "long_axis" in grid.field_data else np.array([0, 0, 1.0])
    length = float(np.ptp(grid.points @ axis))
    arrow = pv.Arrow(start=site_point - direction * 0.12 * length, direction=direction,
                     scale=0.11 * length, tip_length=0.3, tip_radius=0.12, shaft_radius=0.04)
    plotter = pv.Plotter(off_screen=True, window_size=list(window))
    plotter.add_silhouette(undeformed, color="gray", line_width=1.5)
    plotter.add_mesh(surface, scalars=scalars, cmap="turbo", clim=clim, smooth_shading=True,
                     scalar_bar_args={"title": scalar_title, "vertical": True, "fmt": "%.3g",
                                      "position_x": 0.8, "position_y": 0.25, "width": 0.08})
    plotter.add_mesh(arrow, color="black")
    cap = (f"\ncolour scale capped at the {cap_percentile:g}th percentile (the value under the load patch "
           "is not a converged stress: report.md quotes the stresses near the hole)") if capped else ""
    plotter.add_text(f"{title}\ndeformation x{warp:g} (warp factor); grey outline: undeformed; arrow: drill{cap}",
                     font_size=11)
    side = np.cross(axis, direction)
    side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else np.array([1.0, 0, 0])
    centre = np.asarray(undeformed.center)
    plotter.camera.focal_point = centre
    plotter.camera.position = centre + side * 3 * length
    plotter.camera.up = axis
    plotter.reset_camera()
    image = plotter.screenshot(return_img=True)
    plotter.close()
    save_png(path, image)


def save_png(path: Path, image: np.ndarray) -> None:
    """Write an RGB(A) image array as PNG, atomically."""
    from PIL import Image

    with atomic.atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
