"""``build_femur_model``: from a femur description to a cached, region-marked tet mesh with landmarks."""

from __future__ import annotations

import contextlib
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from femstudy.errors import UserError
from femstudy.femur_mesh import REGION_NAMES, Clamps, DrillSite, TetMesh
from femstudy.meshing import cache, landmarks
from femstudy.meshing.frame import Frame
from femstudy.meshing.site_surface import PATCH_RADIUS_MM, SiteSurface, drill_site_on, site_surface

#: Bumped when what the site stage stores changes (the TetWild stage's entries stay valid).
SITE_LAYOUT = 2

log = logging.getLogger(__name__)


#: Largest TetWild target edge [mm] (femstudy.casefile.MAX_MESH_SIZE_MM, docs/checks.md).
MAX_TETWILD_SIZE_MM = 64.0


@dataclass(frozen=True)
class FemurSpec:
    """What the meshed femur depends on.

    surface         : the bone's surface file, or None for the built-in femur
    geometry, mesh, site : sections of a case file (:class:`femstudy.casefile.GeometrySpec`,
                      ``MeshSpec``, ``SiteSpec``) or anything with the same fields
    drill_radius_mm : the drill's radius: the site is refined over twice it
    clamp_length_mm : surface length clamped at each end, along the long axis
    """

    surface: Path | None
    geometry: object
    mesh: object
    site: object
    drill_radius_mm: float
    clamp_length_mm: float


@dataclass
class FemurModel:
    """A meshed femur: see the module docs of :mod:`femstudy.meshing` for each field."""

    mesh: TetMesh
    clamps: Clamps
    site: DrillSite
    frame: Frame
    quality: dict[str, Any]
    stats: dict[str, Any]
    canal_axis: np.ndarray = field(repr=False, default=None)
    surface: SiteSurface | None = field(repr=False, default=None)


def surface_edge_mm(size_mm: float) -> float:
    """Triangle edge the outer and inner surfaces are simplified to before TetWild [mm]:
    0.6 × size within 2.5-8 mm. TetWild's time grows with its input triangles (17,000 take
    99 s, 4,200 take 30 s at 12 mm, docs/meshing.md), and the tets are no finer than this anyway;
    decimation keeps the enclosed volume."""
    return float(np.clip(0.6 * size_mm, 2.5, 8.0))


def surface_file(spec: FemurSpec, cache_dir: Path) -> Path:
    """The surface file to mesh: the spec's, else the built-in femur's (regenerated in the cache
    when the package lacks it)."""
    from femstudy.meshing.builtin_femur import BUILTIN_STL, FemurParameters, generate, write_stl

    if spec.surface is not None:
        return Path(spec.surface)
    if not BUILTIN_STL.is_file():  # a packaging without the data file: regenerate it once
        target = Path(cache_dir) / "builtin" / BUILTIN_STL.name
        if not target.is_file():
            par = FemurParameters()
            write_stl(target, generate(par), header=f"femstudy built-in femur {par.digest()}")
        return target
    return BUILTIN_STL


def mesh_parameters(spec: FemurSpec, size_mm: float, with_site: bool = True) -> dict:
    """Every value that changes the tet mesh (the cache key's parameters); without the site
    refinement's values when ``with_site`` is false (the TetWild stage's key)."""
    g = spec.geometry.model_dump(mode="json")
    g.pop("surface", None)
    # a file with several bodies is meshed only with bodies = "largest", and a file with one
    # is meshed alike either way: the setting never tells two meshes apart
    g.pop("bodies", None)
    m = spec.mesh
    params = {"geometry": g, "size_mm": size_mm, "envelope": m.envelope}
    if with_site and m.refine == "site":
        params.update(refine="site", site_size_mm=m.site_size_mm, site_radius_mm=m.site_radius_mm)
    if with_site:  # the site stage also keeps the surface patch around the site
        params.update(site_position=spec.site.position, site_direction=spec.site.direction,
                      drill_radius_mm=spec.drill_radius_mm, site_layout=SITE_LAYOUT)
    return params


def build_femur_model(spec: FemurSpec, cache_dir: Path = cache.DEFAULT_CACHE_DIR,
                      mesh_size_mm: float | None = None) -> FemurModel:
    """Mesh the femur (or load it from the cache) and locate its clamps and drill site.

    Parameters
    ----------
    spec : FemurSpec
        The surface and the geometry, mesh and site settings.
    cache_dir : Path
        Folder of the mesh cache (created when needed).
    mesh_size_mm : float, optional
        Overrides ``spec.mesh.size_mm``.

    Returns
    -------
    FemurModel
    """
    size = float(mesh_size_mm if mesh_size_mm is not None else spec.mesh.size_mm)
    if not 0 < size <= MAX_TETWILD_SIZE_MM:  # TetWild aborts on inf and runs for minutes past this
        raise UserError(f"mesh size must lie in (0, {MAX_TETWILD_SIZE_MM:g}] mm, got {size:g} mm")
    cache_dir = Path(cache_dir)
    path = surface_file(spec, cache_dir)
    from femstudy.meshing.surface import check_surface_file, file_digest

    check_surface_file(path)
    digest = file_digest(path)
    key = cache.cache_key({"surface_sha256": digest, **mesh_parameters(spec, size)})
    start = time.perf_counter()
    with cache.lock(key, cache_dir):  # a second process asking for this mesh waits, then loads it
        hit = cache.load(key, cache_dir)
        if hit is None:
            # two stages, cached apart: the TetWild mesh (shared by every drill site) and its
            # refinement around this site
            base_key = cache.cache_key({"surface_sha256": digest, **mesh_parameters(spec, size, with_site=False)})
            with cache.lock(base_key, cache_dir) if base_key != key else contextlib.nullcontext():
                base = cache.load(base_key, cache_dir) if base_key != key else None
                if base is None:
                    log.info("meshing %s at %g mm (not cached)", path.name, size)
                    base = _build(spec, path, size)
                    if base_key != key:
                        base = cache.store(base_key, *base, root=cache_dir)
                else:
                    log.info("loaded the cached TetWild mesh %s; refining it at the drill site", base_key[:12])
            arrays, meta = cache.store(key, *_finish(spec, path, size, *base), root=cache_dir)
        else:
            log.info("loaded cached mesh %s (%s)", key[:12], cache_dir)
            arrays, meta = hit
    mesh = TetMesh(arrays["points"], arrays["tets"].astype(np.int64), arrays["region"].astype(np.int8))
    frame = Frame.from_dict(meta["frame"])
    outer = landmarks.outer_faces(mesh, frame)
    clamps = landmarks.clamps(mesh, frame, outer, spec.clamp_length_mm)
    surface = SiteSurface(arrays["site_points"], arrays["site_triangles"].astype(np.int64),
                          np.asarray(meta["site"]["entry_mm"], float), PATCH_RADIUS_MM, frame,
                          (spec.geometry.cortex.midshaft_mm, spec.geometry.cortex.epiphysis_mm),
                          (spec.geometry.canal.proximal_fraction, spec.geometry.canal.distal_fraction))
    site = drill_site_on(surface, spec.site, landmarks.drill_side(frame, spec.site),
                         np.asarray(meta["site"]["centre_mm"], float), spec.drill_radius_mm, mesh)
    stats = dict(meta["stats"])
    stats.update(_landmark_stats(mesh, outer, site, clamps, spec.drill_radius_mm))
    stats.update(cache_hit=hit is not None, cache_key=key, load_or_build_seconds=time.perf_counter() - start,
                 surface_sha256=digest)
    return FemurModel(mesh, clamps, site, frame, meta["quality"], stats, arrays["canal_axis"], surface)


def _landmark_stats(mesh, outer, site, clamps, drill_radius_mm: float) -> dict:
    """Facets under the drill-load disk and their edge lengths; clamped node counts."""
    tri = mesh.points[outer]
    near = np.linalg.norm(tri.mean(axis=1) - site.entry_point, axis=1) < drill_radius_mm
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)
    return {
        "drill_radius_mm": drill_radius_mm,
        "site_facets_in_drill_disk": int(near.sum()),
        "site_edge_mm": float(np.median(edges[near])) if near.any() else float("nan"),
        "site_cortical_thickness_mm": site.cortical_thickness_mm,
        "clamped_nodes": {"proximal": int(clamps.proximal.sum()), "distal": int(clamps.distal.sum())},
    }


@dataclass(frozen=True)
class _Regions:
    """What a build takes from the surface before TetWild, the same for every mesh size that
    simplifies the surface to the same edge: the surface in mm and its frame, the region fields,
    and the simplified outer, inner and canal-patch surfaces."""

    raw: Any
    frame: Frame
    surf_mm: Any
    outer: Any
    fields: Any
    inner: Any
    canal_closed: Any
    patch: Any


#: The last surface's regions, kept for the next build of the same surface, geometry and edge
#: (a sweep's sizes and its remeshes): reading the surface and building its 1 mm region fields
#: take about 6.5 s of each build of the built-in femur. One entry, some tens of MB.
_last_regions: dict[str, _Regions] = {}


def regions_key(spec: FemurSpec, path: Path, edge_mm: float) -> str:
    """What the regions of a build depend on: the surface's bytes, the geometry section (its
    bodies setting included) and the simplified surface's edge, not the mesh size itself."""
    from femstudy.meshing.surface import file_digest

    return cache.cache_key({"surface_sha256": file_digest(path), "geometry": spec.geometry.model_dump(mode="json"),
                            "edge_mm": edge_mm})


def _regions(spec: FemurSpec, path: Path, edge: float) -> _Regions:
    from femstudy.meshing import regions, surface
    from femstudy.meshing.frame import build_frame

    key = regions_key(spec, path, edge)
    kept = _last_regions.get(key)  # read once: a sweep's threads may replace the entry meanwhile
    if kept is not None:
        log.info("regions: reusing this surface's frame and region fields from its last build")
        landmarks.drill_side(kept.frame, spec.site)
        return kept
    raw = surface.read_surface(path, spec.geometry.bodies)
    frame, _ = build_frame(raw.points, raw.triangles, spec.geometry)
    log.info("surface: %d triangles, units %s (x%g to mm), %s femur, length %.1f mm%s", len(raw.triangles),
             frame.units, frame.scale_to_mm, frame.side, frame.length_mm,
             f"; overridden: {', '.join(frame.overridden)}" if frame.overridden else "")
    landmarks.drill_side(frame, spec.site)  # refuse a bad drill direction before anything slow runs
    for note in raw.repairs:
        log.info("repaired: %s", note)
    surf_mm = raw.scaled(frame.scale_to_mm)
    outer = surface.simplify(surf_mm, edge)
    if len(outer.repairs) > len(raw.repairs):
        log.info(outer.repairs[-1])
    log.info("regions: cortex, canal and cancellous fields on a %g mm grid", regions.VOXEL_MM)
    fields = regions.build_fields(outer, frame, spec.geometry)
    inner = _simplified(regions.level_surface(fields, "inner"), edge)
    canal_closed = regions.level_surface(fields, "canal")
    patch = _simplified(regions.level_surface(fields, "canal", clip_by="inner", clip_above=0.25 * fields.spacing), edge)
    log.info("regions: inner surface %d triangles, canal %.0f mm^3", inner.n_cells, canal_closed.volume)
    made = _Regions(raw, frame, surf_mm, outer, fields, inner, canal_closed, patch)
    _last_regions.clear()
    _last_regions[key] = made
    return made


def _build(spec: FemurSpec, path: Path, size: float) -> tuple[dict, dict]:
    from femstudy.meshing import tetra

    edge = surface_edge_mm(size)
    r = _regions(spec, path, edge)
    raw, frame, surf_mm, outer, fields, inner, canal_closed, patch = (
        r.raw, r.frame, r.surf_mm, r.outer, r.fields, r.inner, r.canal_closed, r.patch)
    parts = [(outer.points, outer.triangles)] + [(m.points, m.regular_faces) for m in (inner, patch) if m.n_cells]
    n_in = sum(len(t) for _, t in parts)
    log.info("TetWild: %d input triangles, target edge %g mm, envelope %g", n_in, size, spec.mesh.envelope)
    points, tets, seconds = tetra.tetrahedralize(parts, size, spec.mesh.envelope)
    log.info("TetWild finished in %.1f s: %d tets in its background mesh", seconds, len(tets))
    region = tetra.classify(points, tets, fields, frame, (spec.geometry.canal.proximal_fraction,
                                                          spec.geometry.canal.distal_fraction))
    mesh = tetra.compact(points, tets, region)
    stats = {
        "surface_volume_mm3": surf_mm.volume, "simplified_surface_volume_mm3": outer.volume,
        "canal_volume_mm3": float(canal_closed.volume),
        "canal_midshaft_diameter_mm": _midshaft_canal_diameter(fields, frame),
        "input_triangles": {"surface": len(raw.triangles), "tetwild": n_in},
        "surface_edge_mm": edge, "size_mm": size, "envelope": spec.mesh.envelope,
        "tetwild_seconds": seconds, "tetwild_background_tets": int(len(tets)),
        "repairs": outer.repairs, "surface_file": str(path),
    }
    arrays = {"points": mesh.points, "tets": mesh.tets.astype(np.int32), "region": mesh.region,
              "canal_axis": fields.canal_axis}
    return arrays, {"frame": frame.as_dict(), "stats": stats}


def _finish(spec: FemurSpec, path: Path, size: float, arrays: dict, meta: dict) -> tuple[dict, dict]:
    """The TetWild stage's mesh refined at the drill site (if asked), its quality and statistics,
    and the surface patch around the site (:mod:`femstudy.meshing.site_surface`)."""
    from femstudy.meshing import tetra
    from femstudy.meshing.tetra import signed_volumes

    mesh = TetMesh(arrays["points"], arrays["tets"].astype(np.int64), arrays["region"].astype(np.int8))
    frame = Frame.from_dict(meta["frame"])
    if spec.mesh.refine == "site":
        mesh = _refine_site(mesh, frame, spec, size)
        log.info("refined the drill site to %g mm: %d tets", min(spec.mesh.site_size_mm, size), mesh.n_tets)
    vol = signed_volumes(mesh.points, mesh.tets)
    per_region = {REGION_NAMES[r]: {"tets": int((mesh.region == r).sum()), "volume_mm3": float(vol[mesh.region == r].sum())}
                  for r in REGION_NAMES}
    missing = [name for name, v in per_region.items() if v["tets"] == 0]
    if missing:
        raise UserError(f"the mesh has no {' or '.join(missing)} tets at {size:g} mm; use a smaller "
                        "mesh.size_mm or check geometry.cortex and geometry.canal")
    stats = {"n_points": mesh.n_points, "n_tets": mesh.n_tets, "regions": per_region,
             "tet_volume_mm3": float(vol.sum()), **meta["stats"]}
    patch, centre = _site_patch(spec, path, frame)
    arrays = {"points": mesh.points, "tets": mesh.tets.astype(np.int32), "region": mesh.region,
              "canal_axis": arrays["canal_axis"], "site_points": patch.points,
              "site_triangles": patch.triangles.astype(np.int32)}
    site = {"centre_mm": [float(x) for x in centre], "entry_mm": [float(x) for x in patch.centre]}
    return arrays, {"frame": meta["frame"], "quality": tetra.quality(mesh), "stats": stats, "site": site}


def _site_patch(spec: FemurSpec, path: Path, frame: Frame) -> tuple[SiteSurface, np.ndarray]:
    """The input surface (in mm, not decimated) within :data:`PATCH_RADIUS_MM` of the drill's
    entry point on it, and the centre of the cross-section the drill aims at."""
    from femstudy.meshing import surface

    raw = surface.read_surface(path, spec.geometry.bodies)
    points = raw.points * frame.scale_to_mm
    centre = landmarks.section_centre(points, raw.triangles, frame, spec.site.position)
    entry, _ = landmarks.entry_point(points[raw.triangles], frame, spec.site, centre)
    return site_surface(points, raw.triangles, entry, PATCH_RADIUS_MM, frame, spec.geometry), centre


def _refine_site(mesh: TetMesh, frame: Frame, spec: FemurSpec, size: float) -> TetMesh:
    """Bisect tets around the drill site's entry point down to ``mesh.site_size_mm``, over a
    core of twice the drill radius."""
    from femstudy.meshing import refine

    outer = landmarks.outer_faces(mesh, frame)
    centre = landmarks.section_centre(mesh.points, outer, frame, spec.site.position)
    entry, _ = landmarks.entry_point(mesh.points[outer], frame, spec.site, centre)
    h_site = min(spec.mesh.site_size_mm, size)
    target = refine.site_target(entry, size, h_site, max(spec.mesh.site_radius_mm, 2 * h_site),
                                core_mm=max(2 * spec.drill_radius_mm, h_site))
    return refine.refine(mesh, target)


def _simplified(poly, edge_mm: float):
    """Decimate a level-set surface to triangles of about ``edge_mm``."""
    if poly.n_cells == 0:
        return poly
    if not poly.is_all_triangles:  # polygons, and stray lines or vertices a contour may leave
        poly = poly.triangulate()
        poly.lines, poly.verts = np.empty(0, np.int64), np.empty(0, np.int64)
    target = poly.area / (np.sqrt(3) / 4 * edge_mm ** 2)
    if target < 0.8 * poly.n_cells:
        poly = poly.decimate(1.0 - max(target, 50) / poly.n_cells, volume_preservation=True)
    return poly.clean()


def _midshaft_canal_diameter(fields, frame) -> float:
    """Equivalent diameter √(4A/π) of the canal's cross-section at mid-length [mm]."""
    h = fields.spacing
    idx = np.nonzero(fields.canal > 0)
    if len(idx[0]) == 0:
        return 0.0
    x = fields.origin + h * np.column_stack(idx)
    s = frame.fraction(x)
    n = (np.abs(s - 0.5) * frame.length_mm < h / 2).sum()
    return float(np.sqrt(4 * n * h ** 2 / np.pi))
