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
    """Import pyvista configured for off-screen rendering."""
    import pyvista as pv

    pv.OFF_SCREEN = True
    return pv


def deformed_picture(path: Path, grid, site_point, site_direction, warp: float, title: str,
                     scalars: str = "von_mises_MPa", scalar_title: str = "von Mises [MPa]", clim=None,
                     window=(1400, 1000)) -> None:
    """Render ``grid`` (a pyvista UnstructuredGrid with point vector ``displacement_mm`` and
    ``scalars``) warped by ``warp``, with an arrow marking the drill site; save a PNG."""
    pv = start_offscreen()
    surface = grid.extract_surface(algorithm="dataset_surface").warp_by_vector("displacement_mm", factor=warp)
    site_point = np.asarray(site_point, float)
    direction = np.asarray(site_direction, float)
    length = float(np.ptp(grid.points, axis=0).max())
    arrow = pv.Arrow(start=site_point - direction * 0.12 * length, direction=direction,
                     scale=0.11 * length, tip_length=0.3, tip_radius=0.12, shaft_radius=0.04)
    plotter = pv.Plotter(off_screen=True, window_size=list(window))
    plotter.add_mesh(surface, scalars=scalars, cmap="turbo", clim=clim, smooth_shading=True,
                     scalar_bar_args={"title": scalar_title, "vertical": True, "fmt": "%.3g"})
    plotter.add_mesh(arrow, color="black")
    plotter.add_text(f"{title}\ndeformation x{warp:g} (warp factor)", font_size=11)
    # look at the drill site from the side the drill comes from, long axis vertical on screen
    centre = np.asarray(surface.center)
    plotter.camera.focal_point = centre
    plotter.camera.position = centre - direction * 2.2 * length
    axis = np.asarray(grid.field_data["long_axis"]) if "long_axis" in grid.field_data else np.array([0, 0, 1.0])
    plotter.camera.up = axis
    plotter.reset_camera()
    plotter.camera.zoom(1.15)
    image = plotter.screenshot(return_img=True)
    plotter.close()
    save_png(path, image)


def save_png(path: Path, image: np.ndarray) -> None:
    """Write an RGB(A) image array as PNG, atomically."""
    from PIL import Image

    with atomic.atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
