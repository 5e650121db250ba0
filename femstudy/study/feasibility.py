"""Will a study fit? Elements, DOFs, memory and time estimated from the surface, the mesh
size and the time grid, before any meshing or solving; impossible requests are refused in
one sentence that says what would fit, very long ones need ``force``.

Estimates (docs/solver.md has the measurements they rest on):

- tetrahedra: the bone volume V over the mean TetWild tet volume, 0.1 h³ for a target edge
  h (a regular tet is 0.118 h³), plus the drill-site refinement: the site size h_s over a
  core of twice the drill radius about the entry, graded linearly to h at the site radius
  (:func:`femstudy.meshing.refine.site_target`; the same integral over the half of that
  sphere that is bone). This is a lower bound: at coarse sizes TetWild resolves the surface
  with more, smaller tets (the built-in femur: 39,630 tets at 8 mm against 5,000 from the
  volume alone); it is the fine sizes that need refusing, and there the volume and core terms
  dominate (site_size_mm = 1e-6 would make 4e20 tets in the core alone).
- DOFs: 4.7 per tet for P2 (measured 4.69 on the femur), 0.6 per tet for P1.
- memory of the factorisation: 366 · DOFs^(4/3) + 0.5 GB (direct-solver fill on 3-D meshes,
  calibrated on the femur: 1.7 GB at 100k DOFs);
- time of the factorisation: 1.2e-10 · DOFs² s (3.8 s at 180k DOFs);
- the reduced transient keeps about 200 numbers per step (40 Ritz coordinates for
  displacement, velocity, acceleration and the check): 8 · 200 · steps bytes, for the
  thesis-step march and for the resolved one. The resolved run's steps are its window
  (``resolved_lead_s`` + the breakthrough release + 0.1 s) over 1/``steps_per_period`` of the
  lowest period, estimated from the built-in femur's 560 Hz scaled by √(E/ρ) of the cortex
  and by (455.6 mm / length)²; about 0.3 ms each.
- the hole models (``loads.application = "hole"``), one station at a time: 55,000 · f^3.2
  P2 DOFs at refinement f (docs/hole.md: 55,338 / 190,086 / 744,927 at 1 / 1.5 / 2.25),
  factorised like the femur.

:func:`preflight` is what a study, a run of several cases and a sweep check for every case
before the first one starts: this estimate and the inputs' plausibility
(:mod:`femstudy.study.plausibility`).
"""

from __future__ import annotations

import functools
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.errors import UserError

log = logging.getLogger(__name__)

TET_VOLUME_PER_H3 = 0.1
DOFS_PER_TET = {1: 0.6, 2: 4.7}
FACTOR_SECONDS_PER_DOF2 = 1.2e-10
BYTES_PER_STEP = 8 * 200
#: The built-in femur's lowest natural frequency [Hz] and its length [mm] (with Table 3-1's
#: cortex), from which :func:`lowest_frequency_hz` scales a bone's.
REFERENCE_LOWEST_HZ, REFERENCE_LENGTH_MM = 560.0, 455.6
#: Time of one resolved step [s]: the default case marches 6,943 in about 2 s.
RESOLVED_SECONDS_PER_STEP = 3e-4
#: Memory of meshing per final tetrahedron [bytes]: TetWild's background mesh (about three
#: tets per final one) and the refinement's arrays, generously.
MESH_BYTES_PER_TET = 2000.0
#: Hole-model P2 DOFs per station at refinement 1 and their growth exponent (docs/hole.md).
HOLE_DOFS_AT_1, HOLE_DOFS_EXPONENT = 55_000.0, 3.2
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
    resolved_steps: float = 0.0
    hole_dofs: float = 0.0

    @property
    def resolved_bytes(self) -> float:
        return BYTES_PER_STEP * self.resolved_steps

    @property
    def seconds(self) -> float:
        """The factorisation and the resolved march [s] (the rest is seconds)."""
        return self.factor_s + RESOLVED_SECONDS_PER_STEP * self.resolved_steps


def _tets(volume_mm3: float, size_mm: float, site_mm: float | None, radius_mm: float, core_mm: float = 0.0) -> float:
    tets = volume_mm3 / (TET_VOLUME_PER_H3 * size_mm ** 3)
    if site_mm is not None and site_mm < size_mm:  # the refined sphere around the site, half bone
        radius = max(radius_mm, 2 * site_mm)  # as femstudy.meshing.model._refine_site sets it
        core = min(max(core_mm, site_mm), radius)
        inner = 0.5 * 4 / 3 * np.pi * core ** 3 * (1 / site_mm ** 3 - 1 / size_mm ** 3)
        r = core + np.concatenate([[0.0], np.geomspace(1e-6 * max(radius - core, 1e-9), max(radius - core, 1e-9),
                                                        400)])
        h = site_mm + (size_mm - site_mm) * (r - core) / max(radius - core, 1e-9)
        graded = np.trapezoid(0.5 * 4 * np.pi * r ** 2 * (1 / h ** 3 - 1 / size_mm ** 3), r)
        tets += (inner + graded) / TET_VOLUME_PER_H3
    return float(tets)


def lowest_frequency_hz(case, length_mm: float) -> float:
    """A bone's lowest natural frequency, scaled from the built-in femur's (module docstring)."""
    from femstudy.casefile import TABLE_3_1

    cortex, reference = case.materials.cortical, TABLE_3_1["cortical"]
    wave = math.sqrt(cortex.youngs_modulus_GPa / cortex.density_kg_m3)
    wave_ref = math.sqrt(reference.youngs_modulus_GPa / reference.density_kg_m3)
    return REFERENCE_LOWEST_HZ * wave / wave_ref * (REFERENCE_LENGTH_MM / length_mm) ** 2


def resolved_steps(case, length_mm: float) -> float:
    """Steps of the resolved transient (module docstring); 0 when the case runs none."""
    if not (case.analysis.resolved and case.analysis.modes):
        return 0.0
    from femstudy.drilling import Drill

    release = case.drilling.breakthrough_release_s
    if release == "flute":
        drill = Drill(diameter_mm=case.drill.diameter_mm, point_angle_deg=case.drill.point_angle_deg)
        release = 1.0 / drill.flute_passing_hz(case.drilling.spindle_rpm)
    window = case.analysis.resolved_lead_s + float(release) + 0.1
    return window * lowest_frequency_hz(case, length_mm) * case.analysis.steps_per_period


def hole_dofs(case) -> float:
    """P2 DOFs of one hole-model station (module docstring); 0 without hole models."""
    if case.loads.application != "hole":
        return 0.0
    return HOLE_DOFS_AT_1 * case.loads.refinement ** HOLE_DOFS_EXPONENT


def estimate(case, volume_mm3: float, mesh_size_mm: float | None = None,
             length_mm: float = REFERENCE_LENGTH_MM) -> Estimate:
    """The estimate for ``case`` on a bone of ``volume_mm3`` and ``length_mm``."""
    size = float(mesh_size_mm or case.mesh.size_mm)
    site = case.mesh.site_size_mm if case.mesh.refine == "site" else None
    tets = _tets(volume_mm3, size, site, case.mesh.site_radius_mm, core_mm=case.drill.diameter_mm)
    dofs = DOFS_PER_TET[case.mesh.order] * tets
    steps = int(math.floor(case.time.end_s / case.time.step_s + 1e-9))
    return Estimate(tets, dofs, factorisation_bytes(dofs), FACTOR_SECONDS_PER_DOF2 * dofs ** 2, steps,
                    BYTES_PER_STEP * steps, resolved_steps(case, length_mm), hole_dofs(case))


def surface_size(path: Path, cache_dir: Path | None = None) -> tuple[float, float]:
    """The enclosed volume [mm³] and length [mm] of a surface file, its units guessed from its
    extent like the meshing does (a file that is not a femur is refused here, in one line).
    Read once per file version in a process (a sweep asks for every point) and, with a
    ``cache_dir``, read from there when a study kept it (:func:`keep_surface_size`)."""
    stat = Path(path).stat()
    return _surface_size(str(Path(path).resolve()), stat.st_mtime_ns, stat.st_size,
                         None if cache_dir is None else str(Path(cache_dir).resolve()))


def keep_surface_size(path: Path, cache_dir: Path) -> None:
    """Keep the surface's size in ``cache_dir`` under the file's SHA-256, for the estimates of
    later runs (measuring the built-in femur's surface took 0.2 s of a repeated study's 5 s).
    Called once a study has passed every check: a refused case writes nothing."""
    kept = _kept_size_path(Path(path), Path(cache_dir))
    if kept.is_file():
        return
    volume, length = surface_size(path)
    try:
        kept.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_text(kept, json.dumps({"volume_mm3": volume, "length_mm": length}))
    except OSError as exc:
        log.warning("could not keep the surface's size in %s (%s)", kept.parent, exc)


#: Bumped when the way a surface's volume and length are computed changes.
SIZE_FORMAT = 1


def _kept_size_path(path: Path, cache_dir: Path) -> Path:
    from femstudy.meshing.surface import file_digest

    return cache_dir / "surface-sizes" / f"{file_digest(path)}-{SIZE_FORMAT}.json"


@functools.lru_cache(maxsize=16)
def _surface_size(path: str, mtime_ns: int, size: int, cache_dir: str | None) -> tuple[float, float]:
    if cache_dir is not None:
        try:
            stored = json.loads(_kept_size_path(Path(path), Path(cache_dir)).read_text())
            return float(stored["volume_mm3"]), float(stored["length_mm"])
        except (OSError, ValueError, KeyError, TypeError):
            pass  # not kept, or unreadable: measured
    return _measure_surface(Path(path))


def _measure_surface(path: Path) -> tuple[float, float]:
    from femstudy.meshing.frame import detect_units
    from femstudy.meshing.surface import read_points

    mesh = read_points(path).triangulate()
    extent = float(np.ptp(np.asarray(mesh.points), axis=0).max())
    _, scale, _ = detect_units(extent, "auto")
    return abs(float(mesh.volume)) * scale ** 3, extent * scale


def check_meshing(case, surface: Path, available_bytes: float, cache_dir: Path | None = None) -> Estimate:
    """Refuse (:class:`UserError`) a mesh that cannot be built in ``available_bytes`` of memory
    (:data:`MESH_BYTES_PER_TET`), as ``femstudy mesh`` builds it without solving; the surface's
    size is read from ``cache_dir`` when a study kept it there (:func:`surface_size`)."""
    volume, length = surface_size(surface, cache_dir)
    e = estimate(case, volume, length_mm=length)
    budget = MEMORY_SHARE * available_bytes
    if e.tets * MESH_BYTES_PER_TET > budget:
        site = case.mesh.site_size_mm if case.mesh.refine == "site" else case.mesh.size_mm
        raise UserError(f"mesh.size_mm = {case.mesh.size_mm:g} mm (site {site:g} mm) would make about {e.tets:.2g} "
                        f"tetrahedra, needing about {e.tets * MESH_BYTES_PER_TET / 1e9:.3g} GB to build against "
                        f"{budget / 1e9:.3g} GB usable here; use larger sizes")
    return e


def check(case, surface: Path, available_bytes: float, mesh_size_mm: float | None = None,
          force: bool = False, cache_dir: Path | None = None) -> Estimate:
    """Refuse (:class:`UserError`) a study that cannot fit in ``available_bytes`` of memory, or
    that would take longer than :data:`LONG_S` unless ``force``; return the estimate.
    The surface's size is read from ``cache_dir`` when a study kept it there (:func:`surface_size`)."""
    volume, length = surface_size(surface, cache_dir)
    e = estimate(case, volume, mesh_size_mm, length)
    budget = MEMORY_SHARE * available_bytes
    size = float(mesh_size_mm or case.mesh.size_mm)
    if e.memory_bytes > budget:
        sizes = np.geomspace(size, 64.0, 400)
        fits = next((h for h in sizes if estimate(case, volume, h, length).memory_bytes <= budget), None)
        site = case.mesh.site_size_mm if case.mesh.refine == "site" else None
        if fits is None and site is not None and _tets(0.0, size, site, case.mesh.site_radius_mm,
                                                       case.drill.diameter_mm) > e.tets / 2:
            advice = f"mesh.site_size_mm = {site:g} mm refines the drill site beyond what fits: raise it"
        else:
            advice = f"the smallest size that fits is about {fits:.2g} mm" if fits else "no mesh size fits"
        raise UserError(f"mesh.size_mm = {size:g} mm (site {site if site is not None else size:g} mm) would make "
                        f"about {e.tets:.2g} tetrahedra and {e.dofs:.2g} DOFs, needing about "
                        f"{e.memory_bytes / 1e9:.3g} GB to factorise against {budget / 1e9:.3g} GB usable here; "
                        f"{advice}")
    if e.hole_dofs and factorisation_bytes(e.hole_dofs) > budget:
        raise UserError(f"loads.refinement = {case.loads.refinement:g} would make hole models of about "
                        f"{e.hole_dofs:.2g} DOFs, needing about {factorisation_bytes(e.hole_dofs) / 1e9:.3g} GB to "
                        f"factorise against {budget / 1e9:.3g} GB usable here; lower it (1.5 needs about 8 GB)")
    if e.resolved_bytes > budget:
        raise UserError(f"the resolved transient would march about {e.resolved_steps:.3g} steps (its window "
                        f"analysis.resolved_lead_s + the breakthrough release + 0.1 s, over 1/{case.analysis.steps_per_period}"
                        f" of the lowest period), needing about {e.resolved_bytes / 1e9:.3g} GB against "
                        f"{budget / 1e9:.3g} GB usable here; shorten analysis.resolved_lead_s or "
                        f"drilling.breakthrough_release_s (at {case.drilling.spindle_rpm:g} rpm one flute passes in "
                        f"{60 / 2 / case.drilling.spindle_rpm:.3g} s), or set analysis.resolved = false")
    if e.march_bytes > budget:
        dt = case.time.end_s / (budget / BYTES_PER_STEP)
        raise UserError(f"time.step_s = {case.time.step_s:g} s makes {e.steps:,} steps over {case.time.end_s:g} s, "
                        f"needing about {e.march_bytes / 1e9:.3g} GB against {budget / 1e9:.3g} GB usable here; "
                        f"steps of {dt:.2g} s or longer fit (0.1 ms already resolves a femur's lowest mode)")
    if e.factor_s > LONG_S and not force:
        raise UserError(f"mesh.size_mm = {size:g} mm makes about {e.dofs:.2g} DOFs, estimated to take "
                        f"{e.factor_s / 3600:.2g} h to factorise; pass --force (force=True) to run it anyway")
    if e.seconds > LONG_S and not force:
        raise UserError(f"the resolved transient would march about {e.resolved_steps:.3g} steps, estimated to take "
                        f"{e.seconds / 3600:.2g} h; shorten analysis.resolved_lead_s, or pass --force (force=True) "
                        "to run it anyway")
    line = (f"estimate: at least {e.tets:.3g} tets, {e.dofs:.3g} DOFs, {e.memory_bytes / 1e9:.2g} GB (a lower bound: "
            "coarse meshes resolve the surface with more tets)")
    if line not in _said:  # a run of several cases estimates each case before it starts, and again as it starts
        _said.add(line)
        log.info(line)
    return e


_said: set[str] = set()


def preflight(case, cache_dir: Path, bones_dir: Path | None = None, force: bool = False,
              available_bytes: float | None = None, forceable: bool = True) -> Estimate:
    """Everything about ``case`` that can be judged before any work: the estimate
    (:func:`check`) and the plausibility of its inputs
    (:func:`femstudy.study.plausibility.check_inputs`); a :class:`UserError` when either
    refuses it (offering ``--force`` where it applies, ``forceable``)."""
    from femstudy.fe.linsolve import available_memory_bytes
    from femstudy.meshing.model import surface_file
    from femstudy.study import plausibility
    from femstudy.study.femur import femur_spec

    available = available_memory_bytes() if available_bytes is None else available_bytes
    e = check(case, surface_file(femur_spec(case), cache_dir), available, force=force, cache_dir=cache_dir)
    plausibility.check_inputs(case, bones_dir, force, forceable)
    if case.drilling.depth_mm != "cortex":  # then the loads do not wait for the mesh
        from femstudy.study.loading import case_loading

        plausibility.check_loads(case_loading(case, float(case.drilling.depth_mm), bones_dir), force, forceable)
    return e
