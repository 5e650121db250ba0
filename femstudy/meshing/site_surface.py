"""The bone near a drill site as its surfaces define it, independent of any tet mesh.

The tet mesh approximates the bone: TetWild meshes a surface decimated to triangles of 0.6 ×
the mesh size and an inner cortical surface taken from a 1 mm grid, within an envelope, so the
cortex's thickness under the drill, the entry point and the bone's top around the hole move by
fractions of a millimetre from one global mesh to the next — enough to move the stresses near
the hole by several per cent (docs/hole.md). What happens at the hole is therefore read off the
surfaces themselves: the user's outer surface in mm (not decimated) around the site, and the
cortex rule that builds the regions (:mod:`femstudy.meshing.regions`): bone deeper than the
cortical thickness t(s) below the outer surface is no longer cortex, with the depth measured
exactly to the surface's triangles instead of on a grid. The drill site (entry point, surface
normal, cortex crossed along the drill axis, what lies beyond it) comes from them, and so do
the local hole models' geometry (:mod:`femstudy.hole.femur`). Units: mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femstudy.errors import UserError
from femstudy.femur_mesh import DrillSite, TetMesh
from femstudy.meshing.frame import Frame
from femstudy.meshing.ray_cells import cells_along
from femstudy.meshing.regions import point_triangle_distance, thickness

#: Step along a ray between the samples of the cortex rule [mm] (then refined by bisection).
RAY_STEP_MM = 0.25
#: Bisection steps on the cortex rule's crossing (RAY_STEP_MM / 2^20: round-off).
BISECTIONS = 20
#: Samples along each ray tried in one pass of :meth:`SiteSurface.cortex_crossing`.
SAMPLES_PER_PASS = 8
#: Radius of the surface patch kept around a drill site [mm]: the hole model (radius up to
#: 20 mm, its top smoothed over 4 mm) and the depth of points 12 mm below its top, whose nearest
#: surface lies within about that distance sideways.
PATCH_RADIUS_MM = 40.0
#: How far beyond the cortex the drill axis is probed for bone [mm].
BEYOND_PROBE_MM = 1.0


def ray_hits(origins: np.ndarray, direction: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(rays, triangles) distances along the unit ``direction`` from each origin to each
    triangle (k, 3, 3), inf where a ray misses it (Möller & Trumbore 1997)."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-14 * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origins[:, None, :] - tri[None, :, 0]
    u = np.einsum("rtj,tj->rt", s, p) * inv
    q = np.cross(s, e1[None])
    v = (q @ direction) * inv
    t = np.einsum("tj,rtj->rt", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1)
    return np.where(hit, t, np.inf)


@dataclass(frozen=True)
class SiteSurface:
    """The outer surface near a drill site and the cortex rule of the femur's regions.

    points, triangles : the outer surface within ``radius_mm`` of the site [mm]; the triangles'
        orientation is not used
    centre : the site's entry point the patch was cut around [mm]
    radius_mm : the patch's radius; depths are exact for points closer to the surface than
        the patch reaches beyond them
    frame : the femur's frame (the fraction s of the length along its long axis)
    cortex_mm : (midshaft, epiphysis) cortical thicknesses [mm]
    canal_fractions : (proximal, distal) ends of the canal, fractions of the length
    """

    points: np.ndarray
    triangles: np.ndarray
    centre: np.ndarray
    radius_mm: float
    frame: Frame
    cortex_mm: tuple[float, float]
    canal_fractions: tuple[float, float]

    @property
    def tri(self) -> np.ndarray:
        """(m, 3, 3) the triangles' corners [mm]."""
        return self.points[self.triangles]

    def thickness_mm(self, x: np.ndarray) -> np.ndarray:
        """t(s) [mm] at points (n, 3): the cortex rule's thickness at their level along the bone."""
        from types import SimpleNamespace

        cortex = SimpleNamespace(midshaft_mm=self.cortex_mm[0], epiphysis_mm=self.cortex_mm[1])
        canal = SimpleNamespace(proximal_fraction=self.canal_fractions[0], distal_fraction=self.canal_fractions[1])
        return thickness(self.frame.fraction(np.atleast_2d(x)), cortex, canal)

    def depth_mm(self, x: np.ndarray, candidates: int = 12) -> np.ndarray:
        """(n,) distance from points (n, 3) inside the bone to the outer surface [mm]: exact
        distance to the triangles whose centroids are the ``candidates`` nearest."""
        from scipy.spatial import cKDTree

        x = np.atleast_2d(np.asarray(x, float))
        tri = self.tri
        k = min(candidates, len(tri))
        _, near = cKDTree(tri.mean(axis=1)).query(x, k=k)
        near = near.reshape(len(x), k)
        best = np.full(len(x), np.inf)
        for j in range(k):
            best = np.minimum(best, point_triangle_distance(x, tri[near[:, j]]))
        return best

    def entry(self, origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """(n,) distance along the unit ``direction`` from each origin (outside the bone) to the
        first crossing of the surface [mm], inf where the ray misses the patch."""
        origins = np.atleast_2d(np.asarray(origins, float))
        out = np.full(len(origins), np.inf)
        for i in range(0, len(origins), 64):  # bounds the (rays × triangles) temporaries
            out[i:i + 64] = ray_hits(origins[i:i + 64], np.asarray(direction, float), self.tri).min(axis=1)
        return out

    def cortex_crossing(self, starts: np.ndarray, direction: np.ndarray, reach_mm: float) -> np.ndarray:
        """(n,) distance along ``direction`` from each start point on the outer surface to where
        the cortex rule ends the cortex (depth below the surface = t(s)) [mm], inf where the
        cortex lasts beyond ``reach_mm``: sampled every :data:`RAY_STEP_MM`, then bisected."""
        starts = np.atleast_2d(np.asarray(starts, float))
        d = np.asarray(direction, float)
        s = np.arange(RAY_STEP_MM / 2, reach_mm + RAY_STEP_MM, RAY_STEP_MM)
        x = starts[:, None, :] + s[None, :, None] * d
        t = self.thickness_mm(x.reshape(-1, 3)).reshape(len(starts), len(s))
        # a point s along the ray lies at most s below the surface: none before s = t(x) is beyond
        # the cortex; the others are tried a few samples at a time, until each ray has crossed
        possible, beyond = s[None, :] >= t, np.zeros((len(starts), len(s)), bool)
        for j in range(0, len(s), SAMPLES_PER_PASS):
            ray, step = np.nonzero(possible[:, j:j + SAMPLES_PER_PASS] & ~beyond.any(axis=1)[:, None])
            step += j
            beyond[ray, step] = self.depth_mm(x[ray, step]) - t[ray, step] > 0
        found = beyond.any(axis=1)
        first = np.argmax(beyond[found], axis=1)
        lo = np.where(first > 0, s[np.maximum(first - 1, 0)], 0.0)
        hi = s[first]
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            p = starts[found] + mid[:, None] * d
            out = self.depth_mm(p) - self.thickness_mm(p) > 0
            hi, lo = np.where(out, mid, hi), np.where(out, lo, mid)
        crossing = np.full(len(starts), np.inf)
        crossing[found] = 0.5 * (lo + hi)
        return crossing


#: Radius of the surface around the site whose normals give the local bone axis [mm].
AXIS_RADIUS_MM = 20.0
#: Largest λ_min / λ_mid of the normals' tensor for which the bone is taken as locally
#: cylindrical (a cylinder: 0; a sphere: 1).
CYLINDRICAL = 0.35


def local_axis(surface: SiteSurface, fallback: np.ndarray, radius_mm: float = AXIS_RADIUS_MM) -> tuple[np.ndarray, dict]:
    """The bone's local long axis at the site and how it was found.

    On a locally cylindrical bone (the shaft, the neck) the surface normals are perpendicular to
    its axis: the axis is the eigenvector of the area-weighted normal tensor Σ A n nᵀ over the
    surface within ``radius_mm`` of the entry point with the smallest eigenvalue. Where the
    bone is not cylindrical there (λ_min / λ_mid > :data:`CYLINDRICAL`: the condyles, the
    head) no such axis exists and the femur's long axis ``fallback`` is used. The axis points
    the way ``fallback`` does. Osteons, and so the cortex's stiff and strong direction, follow
    the bone's local axis (docs/failure.md)."""
    tri = surface.tri
    near = np.linalg.norm(tri.mean(axis=1) - surface.centre, axis=1) <= radius_mm
    cross = np.cross(tri[near, 1] - tri[near, 0], tri[near, 2] - tri[near, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    n = cross / np.maximum(2 * area, 1e-300)[:, None]
    w, v = np.linalg.eigh(np.einsum("i,ij,ik->jk", area, n, n))
    ratio = float(w[0] / w[1]) if w[1] > 0 else 1.0
    fallback = np.asarray(fallback, float) / np.linalg.norm(fallback)
    if ratio > CYLINDRICAL:
        return fallback, {"axis": "femur long axis", "cylindrical_ratio": ratio,
                          "why": f"the bone within {radius_mm:g} mm of the site is not cylindrical "
                                 f"(lambda_min/lambda_mid {ratio:.2f} > {CYLINDRICAL:g})"}
    axis = v[:, 0] * np.sign(v[:, 0] @ fallback or 1.0)
    angle = float(np.degrees(np.arccos(np.clip(abs(axis @ fallback), 0.0, 1.0))))
    return axis, {"axis": "local", "cylindrical_ratio": ratio, "angle_to_long_axis_deg": angle,
                  "why": f"surface normals within {radius_mm:g} mm of the site"}


def site_surface(points_mm: np.ndarray, triangles: np.ndarray, centre, radius_mm: float, frame: Frame,
                 geometry) -> SiteSurface:
    """The patch of a surface (points in mm) within ``radius_mm`` of ``centre``, with the cortex
    rule of ``geometry`` (a case's :class:`~femstudy.casefile.GeometrySpec`)."""
    centre = np.asarray(centre, float)
    tri = np.asarray(triangles, np.int64)
    near = np.linalg.norm(points_mm[tri].mean(axis=1) - centre, axis=1) <= radius_mm
    if not near.any():
        raise UserError(f"no part of the bone's surface lies within {radius_mm:g} mm of the drill site")
    kept = tri[near]
    used, local = np.unique(kept, return_inverse=True)
    return SiteSurface(np.asarray(points_mm, float)[used], local.reshape(-1, 3), centre, float(radius_mm), frame,
                       (float(geometry.cortex.midshaft_mm), float(geometry.cortex.epiphysis_mm)),
                       (float(geometry.canal.proximal_fraction), float(geometry.canal.distal_fraction)))


def drill_site_on(surface: SiteSurface, site, side: np.ndarray, centre: np.ndarray, drill_radius_mm: float,
                  mesh: TetMesh) -> DrillSite:
    """The drill site on the surface patch: where a ray from outside on the ``side`` of the
    bone (unit, across the long axis) towards ``centre`` (the cross-section's centre) meets it;
    the outward normal averaged over the drill's footprint (radius ``drill_radius_mm``); the
    drill axis across the long axis; the cortex crossed along it by the cortex rule; and what
    lies :data:`BEYOND_PROBE_MM` past the cortex on the axis in the tet ``mesh``: "cancellous"
    bone, or the "canal" (no bone)."""
    up = surface.frame.up
    start = centre + side * surface.frame.length_mm
    t = float(surface.entry(start, -side)[0])
    if not np.isfinite(t):
        raise UserError(f"the drill direction at site '{site.name}' does not meet the bone surface")
    entry = start - side * t
    tri = surface.tri
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    near = np.linalg.norm(tri.mean(axis=1) - entry, axis=1) < drill_radius_mm
    if not near.any():
        near = np.linalg.norm(tri.mean(axis=1) - entry, axis=1) <= np.linalg.norm(tri.mean(axis=1) - entry, axis=1).min()
    normal = normals[near].sum(axis=0)
    normal = normal / np.linalg.norm(normal)
    if normal @ side < 0:  # a surface's orientation is not relied on: outward faces the drill's side
        normal = -normal
    direction = -(side - (side @ up) * up)
    direction = direction / np.linalg.norm(direction)
    cortex = float(surface.cortex_crossing(entry, direction, 60.0)[0])
    cortex = cortex if np.isfinite(cortex) else 60.0
    probe = entry + (cortex + BEYOND_PROBE_MM) * direction
    inside = bool(cells_along(mesh, probe, direction, [0.0])[0] >= 0)
    return DrillSite(site.name, entry, normal, direction, round(cortex, 3), "cancellous" if inside else "canal")
