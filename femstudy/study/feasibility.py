"""Will a study fit? Elements, DOFs, memory and time estimated from the surface, the mesh
size and the time grid, before any meshing or solving; impossible requests are refused in
one sentence that says what would fit, very long ones need ``force``.

Estimates (docs/solver.md has the measurements they rest on):

- tetrahedra: the bone volume V over the mean TetWild tet volume, 0.1 h³ for a target edge
  h (a regular tet is 0.118 h³), plus the drill-site refinement graded from the site size to
  h (the same integral over the refined sphere). This is a lower bound: at coarse sizes
  TetWild resolves the surface with more, smaller tets (the built-in femur: 39,630 tets at
  8 mm against 5,000 from the volume alone); it is the fine sizes that need refusing, and
  there the volume term dominates.
- DOFs: 4.7 per tet for P2 (measured 4.69 on the femur), 0.6 per tet for P1.
- memory of the factorisation: 366 · DOFs^(4/3) + 0.5 GB (direct-solver fill on 3-D meshes,
  calibrated on the femur: 1.7 GB at 100k DOFs);
- time of the factorisation: 1.2e-10 · DOFs² s (3.8 s at 180k DOFs);
- the reduced transient keeps about 200 numbers per step (40 Ritz coordinates for
  displacement, velocity, acceleration and the check): 8 · 200 · steps bytes.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femstudy.errors import UserError

log = logging.getLogger(__name__)

TET_VOLUME_PER_H3 = 0.1
DOFS_PER_TET = {1: 0.6, 2: 4.7}
FACTOR_SECONDS_PER_DOF2 = 1.2e-10
BYTES_PER_STEP = 8 * 200
#: Above this estimated time a study needs ``force``.
LONG_S = 3600.0
#: Share of the available memory a study may plan to use.
MEMORY_SHARE = 0.8


def factorisation_bytes(dofs: float) -> float:
    """Peak memory of assembling and factorising a P2 elasticity system of ``dofs`` unknowns [bytes]."""
    return 366.0 * dofs ** (4 / 3) + 0.5e9


@dataclass(frozen=True)
class Estimate:
    """The estimated size and cost of a study (see the module docstring)."""

    tets: float
    dofs: float
    memory_bytes: float
    factor_s: float
    steps: int
    march_bytes: float


def _tets(volume_mm3: float, size_mm: float, site_mm: float | None, radius_mm: float) -> float:
    tets = volume_mm3 / (TET_VOLUME_PER_H3 * size_mm ** 3)
    if site_mm is not None and site_mm < size_mm:  # the graded sphere around the site, half bone
        r = np.linspace(0.0, radius_mm, 200)
        h = np.clip(site_mm + (size_mm - site_mm) * r / radius_mm, site_mm, size_mm)
        extra = np.trapezoid(0.5 * 4 * np.pi * r ** 2 * (1 / h ** 3 - 1 / size_mm ** 3), r) / TET_VOLUME_PER_H3
        tets += extra
    return float(tets)


def estimate(case, volume_mm3: float, mesh_size_mm: float | None = None) -> Estimate:
    """The estimate for ``case`` on a bone of ``volume_mm3``."""
    size = float(mesh_size_mm or case.mesh.size_mm)
    site = case.mesh.site_size_mm if case.mesh.refine == "site" else None
    tets = _tets(volume_mm3, size, site, case.mesh.site_radius_mm)
    dofs = DOFS_PER_TET[case.mesh.order] * tets
    steps = int(math.floor(case.time.end_s / case.time.step_s + 1e-9))
    return Estimate(tets, dofs, factorisation_bytes(dofs), FACTOR_SECONDS_PER_DOF2 * dofs ** 2, steps,
                    BYTES_PER_STEP * steps)


def surface_volume_mm3(path: Path) -> float | None:
    """The enclosed volume of a surface file [mm³], its units guessed from its extent like
    the meshing does; None when the file cannot be read (meshing then says why)."""
    from femstudy.meshing.frame import detect_units
    from femstudy.meshing.surface import read_polydata

    try:
        mesh = read_polydata(Path(path)).triangulate()
        extent = float(np.ptp(np.asarray(mesh.points), axis=0).max())
        _, scale, _ = detect_units(extent, "auto")
        return abs(float(mesh.volume)) * scale ** 3
    except (UserError, OSError, ValueError, RuntimeError):
        return None


def check(case, surface: Path, available_bytes: float, mesh_size_mm: float | None = None,
          force: bool = False) -> Estimate | None:
    """Refuse (:class:`UserError`) a study that cannot fit in ``available_bytes`` of memory, or
    that would take longer than :data:`LONG_S` unless ``force``; return the estimate."""
    volume = surface_volume_mm3(surface)
    if volume is None:
        return None
    e = estimate(case, volume, mesh_size_mm)
    budget = MEMORY_SHARE * available_bytes
    size = float(mesh_size_mm or case.mesh.size_mm)
    if e.memory_bytes > budget:
        fits = next((h for h in np.geomspace(size, 64.0, 400)
                     if estimate(case, volume, h).memory_bytes <= budget), None)
        advice = f"the smallest size that fits is about {fits:.2g} mm" if fits else "no mesh size fits"
        raise UserError(f"mesh.size_mm = {size:g} mm would make about {e.tets:.2g} tetrahedra and {e.dofs:.2g} DOFs, "
                        f"needing about {e.memory_bytes / 1e9:.3g} GB to factorise against {budget / 1e9:.3g} GB "
                        f"usable here; {advice}")
    if e.march_bytes > budget:
        dt = case.time.end_s / (budget / BYTES_PER_STEP)
        raise UserError(f"time.step_s = {case.time.step_s:g} s makes {e.steps:,} steps over {case.time.end_s:g} s, "
                        f"needing about {e.march_bytes / 1e9:.3g} GB against {budget / 1e9:.3g} GB usable here; "
                        f"steps of {dt:.2g} s or longer fit (0.1 ms already resolves a femur's lowest mode)")
    if e.factor_s > LONG_S and not force:
        raise UserError(f"mesh.size_mm = {size:g} mm makes about {e.dofs:.2g} DOFs, estimated to take "
                        f"{e.factor_s / 3600:.2g} h to factorise; pass --force (force=True) to run it anyway")
    log.info("estimate: at least %.3g tets, %.3g DOFs, %.2g GB (a lower bound: coarse meshes resolve the surface "
             "with more tets)", e.tets, e.dofs, e.memory_bytes / 1e9)
    return e
