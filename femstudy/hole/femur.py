"""Column tops, bottoms and regions of a local hole model: read off the bone's surfaces
(:func:`surface_columns`, what a study uses) or off a global bone mesh (:func:`femur_columns`).

From the surfaces (:class:`SurfaceColumns`): every column's top is where it meets the user's
outer surface around the site (:class:`femstudy.meshing.site_surface.SiteSurface`), its
cortex ends where the cortex rule of the femur's regions puts the inner cortical surface
(depth below the outer surface = t(s), measured exactly), and below that it ends in the canal
(a free surface) or continues through cancellous bone to the global mesh's next boundary or the
depth cap. None of it depends on the global mesh's size, so a station's geometry is the same on
every global mesh (docs/hole.md).

From a global mesh (:class:`FemurColumns`):

Every column is a ray parallel to the drill axis d through a disk vertex (x₁, x₂) of the
local frame. Its top is the first crossing of the bone's outer surface (triangles
``outer_faces``); its bottom the next crossing of any boundary triangle of the global mesh
after the top (the canal wall, or the far surface) — a free surface — unless that lies
deeper than ``depth_cap_mm`` below the top, in which case the column stops at the cap, a cut
through still-solid bone (Möller & Trumbore 1997 ray–triangle intersection). A cell's region
is the global mesh's region at its centroid; a centroid just outside the global mesh (the
local top's chords cut under the global surface's facets) takes its closest global cell's,
within ``region_tolerance_mm``. The cortex's inner surface, where it meets cancellous bone
(the global mesh's faces between cortical and cancellous cells), is ray-cast the same way;
:class:`SmoothColumns` smooths it and gives it to the local mesh as an interface its layers
follow, and decides the regions near it by the smoothed surface. Units: mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from femstudy.errors import UserError, require
from femstudy.femur_mesh import CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL, TetMesh
from femstudy.hole.frame import HoleFrame
from femstudy.meshing.landmarks import boundary_faces, region_interface
from femstudy.meshing.site_surface import ray_hits

if TYPE_CHECKING:
    from scipy.interpolate import RectBivariateSpline

    from femstudy.meshing.site_surface import SiteSurface

#: Rays per batch in the ray casts (bounds the (rays × triangles) temporaries).
RAY_BATCH = 64
#: Cells whose centroid lies within this depth of the smoothed inner cortical surface take
#: their region from the side of it they are on, not from the global mesh [mm].
INTERFACE_BAND_MM = 1.5
#: Fraction of the local model's columns that must cross the inner cortical surface for the
#: local mesh to follow it.
INTERFACE_COVER = 0.9


class _OuterColumns:
    """What every column source derives from its ``outer_depth``: which columns meet the bone,
    and their tops, refused when one misses the bone."""

    def covers(self, xy: np.ndarray) -> np.ndarray:
        """(n,) True where a column meets the bone's outer surface."""
        return np.isfinite(self.outer_depth(xy))

    def top(self, xy: np.ndarray) -> np.ndarray:
        """(n,) depth ζ of the outer surface on every column [mm]."""
        first = self.outer_depth(xy)
        if not np.all(np.isfinite(first)):
            raise UserError(f"{np.sum(~np.isfinite(first))} columns of the local model miss the bone's outer surface: "
                            "the submodel radius reaches beyond the bone")
        return first


@dataclass(frozen=True)
class FemurColumns(_OuterColumns):
    """Callables for :func:`femstudy.hole.mesh.hole_mesh` on one global mesh and frame."""

    mesh: TetMesh
    frame: HoleFrame
    outer: np.ndarray
    boundary: np.ndarray
    depth_cap_mm: float
    region_tolerance_mm: float
    inner: np.ndarray
    inner_codes: np.ndarray

    #: the raw columns give the local mesh no interface to follow (:class:`SmoothColumns` does)
    interface = None

    def _rays(self, xy: np.ndarray, faces: np.ndarray):
        xy = np.asarray(xy, float)
        lift = float(np.ptp(self.mesh.points, axis=0).max())
        origins = self.frame.to_global(np.column_stack([xy, np.full(len(xy), -lift)]))
        tri = self.mesh.points[faces]
        local = self.frame.to_local(tri.reshape(-1, 3)).reshape(-1, 3, 3)
        reach = np.hypot(local[..., 0], local[..., 1]).min(axis=1)
        edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
        near = reach <= np.hypot(xy[:, 0], xy[:, 1]).max() + edge
        return origins, tri[near], lift

    def outer_depth(self, xy: np.ndarray) -> np.ndarray:
        """(n,) depth ζ of the outer surface on every column [mm], inf where a column misses it."""
        origins, tri, lift = self._rays(xy, self.outer)
        first = np.concatenate([ray_hits(origins[i:i + RAY_BATCH], self.frame.axis, tri).min(axis=1)
                                for i in range(0, len(origins), RAY_BATCH)]) if len(tri) else np.full(len(origins), np.inf)
        return first - lift

    def _first_below(self, xy: np.ndarray, faces: np.ndarray, top: np.ndarray) -> np.ndarray:
        """(n,) depth of the first crossing of ``faces`` below ``top`` on every column [mm] (inf: none)."""
        origins, tri, lift = self._rays(xy, faces)
        gap = 1e-6 * lift
        found = []
        for i in range(0, len(origins), RAY_BATCH):
            t = ray_hits(origins[i:i + RAY_BATCH], self.frame.axis, tri) - lift
            found.append(np.where(t > top[i:i + RAY_BATCH, None] + gap, t, np.inf).min(axis=1, initial=np.inf))
        return np.concatenate(found) if found else np.full(len(xy), np.inf)

    def bottom(self, xy: np.ndarray, top: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(n,) depth of each column's bottom [mm] and (n,) True where it is a free surface
        (``top``: the columns' :meth:`top`, when already cast)."""
        top = self.top(xy) if top is None else top
        exit_depth = self._first_below(xy, self.boundary, top)
        free = exit_depth <= top + self.depth_cap_mm
        return np.where(free, exit_depth, top + self.depth_cap_mm), free

    def inner_depth(self, xy: np.ndarray, top: np.ndarray) -> np.ndarray:
        """(n,) depth of the cortex's inner surface against cancellous bone on every column below
        its ``top`` [mm] (inf where the column meets none)."""
        return self._first_below(xy, self.inner, top) if len(self.inner) else np.full(len(xy), np.inf)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(n,) True where a tetrahedron of the global mesh holds the point."""
        import pyvista as pv

        grid = pv.UnstructuredGrid({pv.CellType.TETRA: self.mesh.tets}, self.mesh.points)
        return np.asarray(grid.find_containing_cell(np.atleast_2d(points)), dtype=np.int64).reshape(-1) >= 0

    def region(self, points: np.ndarray) -> np.ndarray:
        """(n,) global region code at each point (0 farther than the tolerance from the mesh)."""
        import pyvista as pv

        grid = pv.UnstructuredGrid({pv.CellType.TETRA: self.mesh.tets}, self.mesh.points)
        cell = np.asarray(grid.find_containing_cell(points), dtype=np.int64)
        missed = np.flatnonzero(cell < 0)
        if len(missed):
            closest, nearest = grid.find_closest_cell(points[missed], return_closest_point=True)
            near = np.linalg.norm(nearest - points[missed], axis=1) <= self.region_tolerance_mm
            cell[missed] = np.where(near, closest, -1)
        return np.where(cell >= 0, self.mesh.region[np.maximum(cell, 0)], 0)


def femur_columns(mesh: TetMesh, outer_faces: np.ndarray, frame: HoleFrame, depth_cap_mm: float,
                  region_tolerance_mm: float = 0.5) -> FemurColumns:
    """Top, bottom and region callables of a local hole model on the global mesh ``mesh``.

    Parameters
    ----------
    mesh : the global bone mesh (no hole)
    outer_faces : (k, 3) point indices of its outer (periosteal) surface triangles
    frame : the hole's frame (entry point on the outer surface, drill axis into the bone)
    depth_cap_mm : deepest column below its top; a column still in bone there ends in a cut
    region_tolerance_mm : how far outside the global mesh a cell centroid may lie and still
        take its closest cell's region

    Returns
    -------
    :class:`FemurColumns` with ``top``, ``bottom`` and ``region`` for :func:`~femstudy.hole.mesh.hole_mesh`

    Examples
    --------
    >>> columns = femur_columns(model.mesh, outer, HoleFrame.along(site.entry_point, site.direction), 12.0)  # doctest: +SKIP
    >>> hole = hole_mesh(columns.frame, 2.7, 90.0, 8.0, tips, columns.top, columns.bottom, columns.region)  # doctest: +SKIP
    """
    require(depth_cap_mm > 0, f"the depth cap must be positive, got {depth_cap_mm} mm")
    outer_faces = np.asarray(outer_faces, dtype=np.int64).reshape(-1, 3)
    require(len(outer_faces) > 0, "the outer surface has no triangles")
    inner, inner_codes = region_interface(mesh, CORTICAL)
    return FemurColumns(mesh, frame, outer_faces, boundary_faces(mesh), float(depth_cap_mm),
                        float(region_tolerance_mm), inner, inner_codes)


#: Spacing of the grid on which the inner cortical surface is found and splined [mm].
INTERFACE_GRID_MM = 0.5
#: How far below the inner cortical surface a column is probed for bone: no global tet there is
#: the canal [mm] (more than the global inner surface's own error, less than the thinnest
#: cancellous layer the regions keep, ``canal.min_cancellous_mm`` = 3 mm by default).
CANAL_PROBE_MM = 2.0


@dataclass(frozen=True)
class SurfaceColumns(_OuterColumns):
    """Column tops, cortex and bottoms of a local hole model from the site's surfaces (module
    docstring); the global mesh (``mesh_columns``) decides only between canal and cancellous
    bone below the cortex and gives the bottoms in cancellous bone."""

    surface: SiteSurface
    mesh_columns: FemurColumns
    frame: HoleFrame
    depth_cap_mm: float
    inner_spline: RectBivariateSpline
    cancellous_code: int

    @property
    def inner_codes(self) -> np.ndarray:
        return np.array([self.cancellous_code])

    @property
    def lift(self) -> float:
        return 2.0 * self.surface.radius_mm

    def outer_depth(self, xy: np.ndarray) -> np.ndarray:
        """(n,) depth ζ of the outer surface on every column [mm], inf where a column misses it."""
        xy = np.atleast_2d(np.asarray(xy, float))
        origins = self.frame.to_global(np.column_stack([xy, np.full(len(xy), -self.lift)]))
        return self.surface.entry(origins, self.frame.axis) - self.lift

    def inner_depth(self, xy: np.ndarray, top: np.ndarray) -> np.ndarray:
        """(n,) ζ of the inner cortical surface by the cortex rule (splined over the disk) [mm]."""
        xy = np.atleast_2d(np.asarray(xy, float))
        return top + self.inner_spline(xy[:, 0], xy[:, 1], grid=False)

    def bottom(self, xy: np.ndarray, top: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(n,) ζ of each column's bottom and (n,) True where it is a free surface: the inner
        cortical surface over the canal, else the global mesh's next boundary below it or the cap."""
        xy = np.atleast_2d(np.asarray(xy, float))
        top = self.top(xy) if top is None else top
        inner = self.inner_depth(xy, top)
        probe = self.frame.to_global(np.column_stack([xy, inner + CANAL_PROBE_MM]))
        canal = (inner < top + self.depth_cap_mm) & ~self.mesh_columns.contains(probe)
        exit_depth = np.where(canal, inner, self.mesh_columns._first_below(xy, self.mesh_columns.boundary, inner))
        free = exit_depth <= top + self.depth_cap_mm
        return np.where(free, exit_depth, top + self.depth_cap_mm), free

    def region(self, points: np.ndarray) -> np.ndarray:
        """(n,) cortical where the cortex rule holds the point, else the cancellous code."""
        points = np.atleast_2d(np.asarray(points, float))
        cortical = self.surface.depth_mm(points) < self.surface.thickness_mm(points)
        return np.where(cortical, CORTICAL, self.cancellous_code)


def surface_columns(surface, mesh: TetMesh, outer_faces: np.ndarray, frame: HoleFrame, depth_cap_mm: float,
                    radius_mm: float) -> SurfaceColumns:
    """Columns of a local hole model of radius up to ``radius_mm`` from the site's surface patch
    (:class:`femstudy.meshing.site_surface.SiteSurface`) and the cortex rule, the global
    ``mesh`` (its ``outer_faces``) telling canal from cancellous bone below the cortex.

    Examples
    --------
    >>> columns = surface_columns(model.surface, model.mesh, outer, frame, 12.0, 12.0)  # doctest: +SKIP
    """
    from scipy.interpolate import RectBivariateSpline

    require(depth_cap_mm > 0, f"the depth cap must be positive, got {depth_cap_mm} mm")
    require(radius_mm + depth_cap_mm < surface.radius_mm,
            f"the local model ({radius_mm:g} mm wide, {depth_cap_mm:g} mm deep) reaches beyond the "
            f"{surface.radius_mm:g} mm surface patch kept around the site")
    raw = femur_columns(mesh, outer_faces, frame, depth_cap_mm)
    axis = np.arange(-radius_mm - INTERFACE_GRID_MM, radius_mm + 1.5 * INTERFACE_GRID_MM, INTERFACE_GRID_MM)
    X, Y = np.meshgrid(axis, axis, indexing="ij")
    xy = np.column_stack([X.ravel(), Y.ravel()])
    lift = 2.0 * surface.radius_mm
    top = surface.entry(frame.to_global(np.column_stack([xy, np.full(len(xy), -lift)])), frame.axis) - lift
    hit = np.isfinite(top)
    below = np.full(len(xy), depth_cap_mm + 1.0)
    starts = frame.to_global(np.column_stack([xy[hit], top[hit]]))
    below[hit] = np.minimum(surface.cortex_crossing(starts, frame.axis, depth_cap_mm + 1.0), depth_cap_mm + 1.0)
    if not hit.all():  # past the bone's edge: the nearest columns' values, so the spline stays smooth
        from scipy.spatial import cKDTree

        _, nearest = cKDTree(xy[hit]).query(xy[~hit])
        below[~hit] = below[hit][nearest]
    spline = RectBivariateSpline(axis, axis, below.reshape(X.shape), kx=3, ky=3)
    entry = frame.to_global(np.zeros((1, 3)))
    mid = 0.5 * sum(surface.canal_fractions)
    code = CANCELLOUS_PROXIMAL if float(surface.frame.fraction(entry)[0]) < mid else CANCELLOUS_DISTAL
    return SurfaceColumns(surface, raw, frame, float(depth_cap_mm), spline, code)


@dataclass(frozen=True)
class SmoothColumns:
    """Column tops and bottoms of a :class:`FemurColumns` smoothed at a stated length.

    The global mesh's surfaces are decimated polyhedra (facets of several mm whose edges are
    kinks of tens of degrees); ray-cast column by column they give the local model corners
    that move with its refinement. Here the top and bottom depths are ray-cast once on a fixed
    grid (``spacing_mm``) over the disk, convolved with a Gaussian of standard deviation
    ``smoothing_mm`` and interpolated by bicubic splines, so every refinement of the local
    model sees one smooth surface. The bottom's exit depth is clipped 1 mm below the cap before
    smoothing; a column is free where the smoothed exit lies above the cap. The cortex's inner
    surface against cancellous bone, where at least :data:`INTERFACE_COVER` of the columns
    cross it above their bottom, is smoothed the same way (``inner_spline``, its depth below
    the top) and is the :attr:`interface` the local mesh follows; within
    :data:`INTERFACE_BAND_MM` of it a cell is cortical above it and cancellous (``inner_code``)
    below. Other regions are the global mesh's (unsmoothed).
    """

    raw: FemurColumns
    top_spline: RectBivariateSpline
    exit_spline: RectBivariateSpline
    inner_spline: RectBivariateSpline | None = None
    inner_code: int = 0

    @property
    def frame(self) -> HoleFrame:
        return self.raw.frame

    def top(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, float)
        return self.top_spline(xy[:, 0], xy[:, 1], grid=False)

    def bottom(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xy = np.asarray(xy, float)
        top = self.top(xy)
        exit_depth = top + self.exit_spline(xy[:, 0], xy[:, 1], grid=False)
        free = exit_depth <= top + self.raw.depth_cap_mm
        return np.where(free, exit_depth, top + self.raw.depth_cap_mm), free

    @property
    def interface(self):
        """Callable (n, 2) → (n,) ζ of the smoothed inner cortical surface [mm], or None."""
        if self.inner_spline is None:
            return None

        def depth(xy: np.ndarray) -> np.ndarray:
            xy = np.asarray(xy, float)
            return self.top(xy) + self.inner_spline(xy[:, 0], xy[:, 1], grid=False)
        return depth

    def region(self, points: np.ndarray) -> np.ndarray:
        codes = self.raw.region(points)
        if self.inner_spline is None:
            return codes
        local = self.frame.to_local(np.asarray(points, float))
        below = local[:, 2] - self.interface(local[:, :2])
        near = (codes != 0) & (np.abs(below) < INTERFACE_BAND_MM)
        return np.where(near, np.where(below < 0, CORTICAL, np.where(codes == CORTICAL, self.inner_code, codes)), codes)


def smooth_columns(columns: FemurColumns, radius_mm: float, smoothing_mm: float = 1.0,
                   spacing_mm: float = 0.2) -> SmoothColumns:
    """Smoothed top and bottom callables over the disk of ``radius_mm`` (:class:`SmoothColumns`).

    Parameters
    ----------
    columns : the ray-cast columns (:func:`femur_columns`)
    radius_mm : the local model's radius R_sub [mm]
    smoothing_mm : standard deviation of the Gaussian [mm]
    spacing_mm : ray grid spacing [mm]

    Returns
    -------
    SmoothColumns

    Examples
    --------
    >>> smooth = smooth_columns(femur_columns(mesh, outer, frame, 12.0), 8.0)  # doctest: +SKIP
    >>> hole = hole_mesh(frame, 2.7, 90.0, 8.0, tips, smooth.top, smooth.bottom, smooth.region)  # doctest: +SKIP
    """
    from scipy.interpolate import RectBivariateSpline
    from scipy.ndimage import gaussian_filter

    require(smoothing_mm > 0 and spacing_mm > 0, "the smoothing length and ray spacing must be positive")
    reach = radius_mm + 4 * smoothing_mm + spacing_mm
    axis = np.arange(-reach, reach + spacing_mm / 2, spacing_mm)
    X, Y = np.meshgrid(axis, axis, indexing="ij")
    xy = np.column_stack([X.ravel(), Y.ravel()])
    inside = np.hypot(xy[:, 0], xy[:, 1]) <= reach
    top = np.full(len(xy), np.nan)
    top[inside] = columns.outer_depth(xy[inside])
    inside &= np.isfinite(top)  # past the bone's edge the average is over the columns on bone
    top[~inside] = np.nan
    exit_below = np.full(len(xy), np.nan)
    bottom, free = columns.bottom(xy[inside], top[inside])
    exit_below[inside] = np.where(free, bottom - top[inside], columns.depth_cap_mm + 1.0)
    inner_below = np.full(len(xy), np.nan)
    inner_below[inside] = columns.inner_depth(xy[inside], top[inside]) - top[inside]
    inner_below[~(inner_below < exit_below)] = np.nan
    in_disk = inside & (np.hypot(xy[:, 0], xy[:, 1]) <= radius_mm)
    has_inner = np.isfinite(inner_below[in_disk]).mean() >= INTERFACE_COVER  # no inner faces: all NaN
    sigma = smoothing_mm / spacing_mm

    def smoothed(values: np.ndarray) -> RectBivariateSpline:
        grid = values.reshape(X.shape)
        weight = gaussian_filter(np.isfinite(grid).astype(float), sigma, mode="constant")
        field = gaussian_filter(np.nan_to_num(grid), sigma, mode="constant") / np.maximum(weight, 1e-12)
        return RectBivariateSpline(axis, axis, field, kx=3, ky=3)

    inner = {}
    if has_inner:
        codes, counts = np.unique(columns.inner_codes, return_counts=True)
        inner = {"inner_spline": smoothed(inner_below), "inner_code": int(codes[np.argmax(counts)])}
    return SmoothColumns(columns, smoothed(top), smoothed(np.minimum(exit_below, columns.depth_cap_mm + 1.0)), **inner)
