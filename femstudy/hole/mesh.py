"""A column mesh around a drill axis whose holes advance through depth stations.

Geometry (local frame of :mod:`femstudy.hole.frame`: r from the axis, depth ζ along d):

* the 2-D disk r ≤ R_sub of :func:`femstudy.hole.rings.disk`, with a ring on the hole
  circle r = R (the drill radius);
* a column along d through every disk vertex, from the bone's top surface ζ_top (a
  callable) to its bottom ζ_bottom (a callable that also says whether the bottom is a free
  surface or a cut through still-solid bone);
* layer surfaces ζ_j = s_j + c(r) + w(r)(ζ_top − ζ_top(0)), clipped to [ζ_top, ζ_bottom],
  with c(r) = (R − r) cot(β/2) for r < R (0 outside) the drill-point cone of point angle β,
  and w(r) a smooth step from 0 at r ≤ R to 1 at r ≥ 2R. Inside and on the hole circle the
  layers are therefore exact cones and planes at depth s_j below the entry point; far from
  the hole they follow the top surface. A station with its drill tip at depth t_k has its
  wall–cone corner at s_k = t_k − l, l = R cot(β/2) the cone length (1.35 mm for Ø2.7 mm,
  90°), and s_k is one of the layer offsets, so the station's hole (the cylinder r < R down
  to the cone ζ = s_k + c(r)) is exactly a union of cells. The offsets inside the cone
  region (s < 0) are those that put a layer's rim on a disk ring; the offsets s ≥ 0 are
  graded from ``axial_mm`` at the top and at every station's corner to ``axial_max_mm``,
  and are ``ligament_mm`` apart through the bone ahead of the deepest tip on the axis (the
  ligament between the deepest cone and the bottom, which bends under the thrust: one 0.4 mm
  layer there made the stresses beside it converge at order ~1 instead of 2, docs/hole.md),
  at most ``ligament_depth_mm`` ahead of it.
* optionally one more layer, at offset s_I, that follows a material interface ζ_I(x₁, x₂)
  (the cortex's inner surface, where the hole passes from cortical into cancellous bone): on
  and outside the hole circle every column's offsets are moved by a hat function of s that
  carries s_I to ζ_I and keeps the station corners in place (:func:`_conforming_offsets`), so
  the interface is a surface of element faces there rather than a staircase of cells whose
  centroids fall on either side of it, and the stresses beside the wall, which jump across it,
  are read on the right side at every refinement. Inside the hole circle the layers move
  only between the corners around s_I, so they follow the interface where it lies between
  those corners' cones and miss it elsewhere (bone under the tip, drilled by later stations).
  Where the interface crosses a corner on the hole circle itself (a steeply inclined cortex,
  as at the femoral neck), it is not followed at all (:data:`INTERFACE_ON_WALL`).
  A vertex closer than ``snap`` of a layer spacing to the top or bottom moves onto it, on a
  station's cone too: a cone breaking through the bottom reaches it up to snap × the layer
  spacing early, rather than leave a sliver-thin sheet of bone (up to 0.18 mm with the
  default 0.4 mm layers at the stations; it vanishes under refinement).
* every disk triangle × layer is a prism cut into three tetrahedra by the minimum-index rule
  (:mod:`femstudy.hole.prisms`); coincident vertices of a column are merged first, so
  collapsed cells drop out and the mesh stays conforming.

A tetrahedron inside the hole circle between layers j and j+1 is drilled away from the first
station with s_k ≥ s_{j+1} (its ``station`` label); the others are never drilled (−1).

Boundary labels: ``hole_wall`` and ``hole_bottom`` (the exposed cone) per station; ``top``
(the bone surface the drill enters), ``bottom_free`` (where the column leaves the bone),
``cut_bottom`` (a capped bottom in solid bone), ``cut_lateral`` (r = R_sub) and ``void``
(surfaces of cells the region callable marked empty).

Units: mm.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from femstudy.errors import require
from femstudy.femur_mesh import CORTICAL, TetMesh
from femstudy.hole.frame import HoleFrame
from femstudy.hole.prisms import split_prisms
from femstudy.hole.rings import Disk, disk, graded_points
from femstudy.meshing.tetra import orient, quality, signed_volumes

log = logging.getLogger(__name__)

LABELS = ("hole_wall", "hole_bottom", "top", "bottom_free", "cut_bottom", "cut_lateral", "void")
#: Face labels on which a submodel takes the global model's displacements.
CUT_LABELS = ("cut_bottom", "cut_lateral")
#: Fraction of the hole circle on which the interface layer must reach the interface for the
#: mesh to follow it: where the interface crosses a station's corner there, the pinned corners
#: would squeeze the layers beside the wall and the interface would still be missed.
INTERFACE_ON_WALL = 0.75


@dataclass(frozen=True)
class Resolution:
    """Element sizes of the column mesh, with one knob for convergence studies.

    refinement   : every length below is divided by it, the hole-circle vertex count and
                   the number of elements per growth are multiplied by it (growth → growth^(1/refinement)),
                   so refinement 1, 1.5, 2.25 is a ladder h, h/1.5, h/2.25
    n_wall       : vertices on the hole circle at refinement 1 (rounded to a multiple of 4)
    wall_mm      : radial ring spacing at the hole circle [mm]
    growth       : spacing growth per element away from the hole circle, the top and the stations
    axial_mm     : layer thickness at the top and at every station's cone [mm]
    axial_max_mm : largest layer thickness [mm]
    ligament_mm  : layer thickness in the bone ahead of the deepest station's tip, from its cone
                   down to the bottom on the axis (the ligament that bends under the thrust) [mm]
    ligament_depth_mm : how far ahead of the deepest tip the ``ligament_mm`` layers reach at most,
                   not scaled by the refinement: bone thicker than that ahead of the tip is no thin
                   ligament, and beyond it the layers grow by ``growth`` [mm]
    snap         : fraction of a layer spacing within which a vertex moves onto the top or bottom
    """

    refinement: float = 1.0
    n_wall: int = 24
    wall_mm: float = 0.3
    growth: float = 1.4
    axial_mm: float = 0.4
    axial_max_mm: float = 0.8
    ligament_mm: float = 0.1
    ligament_depth_mm: float = 1.0
    snap: float = 0.45

    def __post_init__(self) -> None:
        require(self.refinement > 0 and self.n_wall >= 8 and self.wall_mm > 0 and self.growth >= 1
                and 0 < self.axial_mm <= self.axial_max_mm and 0 < self.ligament_mm <= self.axial_mm
                and self.ligament_depth_mm > 0 and 0 <= self.snap < 0.5,
                f"invalid hole-mesh resolution {self}")

    @property
    def scaled(self) -> dict:
        """The sizes at this refinement: n_wall, wall_mm, growth, axial_mm, axial_max_mm, ligament_mm."""
        f = self.refinement
        return {"n_wall": 4 * max(2, int(round(self.n_wall * f / 4))), "wall_mm": self.wall_mm / f,
                "growth": self.growth ** (1.0 / f), "axial_mm": self.axial_mm / f,
                "axial_max_mm": self.axial_max_mm / f, "ligament_mm": self.ligament_mm / f}


@dataclass(frozen=True)
class HoleStation:
    """The local model at one depth station.

    index            : station number (−1: nothing drilled yet)
    tip_depth_mm     : drill-tip depth below the entry point along d [mm] (NaN at −1)
    corner_depth_mm  : depth of the wall–cone corner, tip − cone length [mm]
    mesh             : the station's tetrahedra (points shared with the :class:`HoleMesh`)
    faces            : label → (k, 3) point indices of the boundary faces (labels in :data:`LABELS`)
    kept             : (n_tets of the HoleMesh,) True for the tetrahedra in this station
    """

    index: int
    tip_depth_mm: float
    corner_depth_mm: float
    mesh: TetMesh
    faces: dict[str, np.ndarray]
    kept: np.ndarray
    hole: "HoleMesh" = field(repr=False)

    @property
    def cut_faces(self) -> np.ndarray:
        """(k, 3) faces where the submodel takes the global displacements."""
        return np.concatenate([self.faces[name] for name in CUT_LABELS])


@dataclass(frozen=True)
class HoleMesh:
    """A column mesh with depth stations; see the module docstring.

    mesh              : every tetrahedron (nothing drilled), positively oriented
    station           : (n_tets,) −1 never drilled, k drilled away from station k on
    tip_depths_mm     : (K,) drill-tip depth of every station below the entry point [mm]
    faces             : label → (k, 3) boundary faces of the undrilled mesh
    in_hole           : (n_tets,) True for tetrahedra inside the hole circle
    point_column      : (n_points,) the disk vertex (column) of every point
    column_top_mm     : (n_columns,) ζ of the top surface on every column [mm]
    layer_offsets_mm  : (L,) the layer offsets s_j [mm]
    quality           : :func:`femstudy.meshing.tetra.quality` of ``mesh``
    """

    frame: HoleFrame
    radius_mm: float
    point_angle_deg: float
    submodel_radius_mm: float
    resolution: Resolution
    mesh: TetMesh
    station: np.ndarray
    tip_depths_mm: np.ndarray
    faces: dict[str, np.ndarray]
    in_hole: np.ndarray
    point_column: np.ndarray
    column_top_mm: np.ndarray
    layer_offsets_mm: np.ndarray
    disk: Disk = field(repr=False)
    quality: dict[str, Any] = field(default_factory=dict)

    @property
    def cone_length_mm(self) -> float:
        """l = R cot(β/2) [mm]."""
        return self.radius_mm / np.tan(np.radians(self.point_angle_deg) / 2)

    @property
    def point_top_depth(self) -> np.ndarray:
        """(n_points,) ζ of the top surface on every point's column [mm]."""
        return self.column_top_mm[self.point_column]

    @property
    def hole_top_mm(self) -> float:
        """The highest top-surface depth on the hole circle [mm]: where the wall begins."""
        return float(self.column_top_mm[self.disk.ring == self.disk.hole_ring].min())

    @property
    def n_stations(self) -> int:
        return len(self.tip_depths_mm)

    def at_station(self, k: int) -> HoleStation:
        """The mesh and labelled faces with the hole drilled to station ``k`` (−1: undrilled).

        Parameters
        ----------
        k : station index, −1 ≤ k < n_stations

        Returns
        -------
        :class:`HoleStation`

        Examples
        --------
        >>> station = hole.at_station(0)  # doctest: +SKIP
        >>> station.faces["hole_bottom"].shape  # doctest: +SKIP
        (96, 3)
        """
        require(-1 <= k < self.n_stations, f"station {k} does not exist (0 to {self.n_stations - 1}, or −1)")
        kept = (self.station < 0) | (self.station > k)
        tets = self.mesh.tets[kept]
        faces, owner = _boundary_faces(tets)
        key = _face_keys(faces, len(self.mesh.points))
        labels = {}
        full_keys = {name: _face_keys(f, len(self.mesh.points)) for name, f in self.faces.items()}
        interface = np.ones(len(faces), bool)
        for name, keys in full_keys.items():
            hit = np.isin(key, keys)
            labels[name] = faces[hit]
            interface &= ~hit
        inside = self.in_hole[kept][owner]
        labels["hole_wall"] = faces[interface & ~inside]
        labels["hole_bottom"] = faces[interface & inside]
        tip = float(self.tip_depths_mm[k]) if k >= 0 else float("nan")
        return HoleStation(k, tip, float(tip - self.cone_length_mm), TetMesh(self.mesh.points, tets, self.mesh.region[kept]),
                           labels, kept, self)

    def removed_volume_mm3(self, k: int) -> float:
        """Volume of the tetrahedra drilled away by station ``k`` [mm³]."""
        gone = (self.station >= 0) & (self.station <= k)
        return float(signed_volumes(self.mesh.points, self.mesh.tets[gone]).sum())

    def summary(self) -> dict:
        """Sizes and quality, JSON-ready."""
        return {"n_points": self.mesh.n_points, "n_tets": self.mesh.n_tets, "n_stations": self.n_stations,
                "n_wall": int(self.disk.ring_counts[self.disk.hole_ring]), "n_rings": len(self.disk.ring_radii),
                "n_layers": len(self.layer_offsets_mm), "min_dihedral_deg": self.quality.get("min_dihedral_deg"),
                "refinement": self.resolution.refinement}


def _face_keys(faces: np.ndarray, n: int) -> np.ndarray:
    s = np.sort(faces, axis=1).astype(np.int64)
    return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]


def _boundary_faces(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces (k, 3) that belong to one tetrahedron only, and that tetrahedron."""
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    owner = np.tile(np.arange(len(tets)), 4)
    key = _face_keys(faces, int(tets.max()) + 1)
    _, first, counts = np.unique(key, return_index=True, return_counts=True)
    once = first[counts == 1]
    return faces[once], owner[once]


def _blend(r: np.ndarray, R: float) -> np.ndarray:
    """w(r): 0 for r ≤ R, 1 for r ≥ 2R, a cubic smooth step in between."""
    t = np.clip((r - R) / R, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _layer_offsets(disk_: Disk, cot: float, corners: np.ndarray, s_max: float, sizes: dict,
                   ligament: tuple[float, float] | None, interface: float | None = None) -> np.ndarray:
    """s_j: the cone-region offsets −(R − r_i) cot(β/2) of the rings inside the hole, then
    offsets graded from 0 to s_max with the station corners (and the ``interface`` offset, if
    any) among them: ``axial_mm`` at 0, at the corners and at the interface, ``ligament_mm``
    over the offsets ``ligament`` = (a, b) of the bone ahead of the deepest tip (None: drilled
    through), growing by ``growth`` per element away from them up to ``axial_max_mm``."""
    R = disk_.ring_radii[disk_.hole_ring]
    negative = -(R - disk_.ring_radii[:disk_.hole_ring]) * cot
    extra = [] if interface is None else [interface]
    refine_at = np.concatenate([[0.0], corners, extra])
    g, h0, h_max, h_lig = sizes["growth"], sizes["axial_mm"], sizes["axial_max_mm"], sizes["ligament_mm"]

    def size(s):
        distance = np.abs(s[:, None] - refine_at[None, :]).min(axis=1)
        h = np.minimum(h_max, h0 + (g - 1.0) * distance)
        if ligament is None:
            return h
        outside = np.maximum(np.maximum(ligament[0] - s, s - ligament[1]), 0.0)
        return np.minimum(h, h_lig + (g - 1.0) * outside)

    fixed = np.unique(np.concatenate([[0.0, s_max], corners[(corners > 0) & (corners < s_max)], extra]))
    return np.concatenate([negative, graded_points(fixed, size)])


#: Least fraction of its nominal thickness a layer keeps when the interface layer is carried
#: towards a pinned one; beyond that the interface layer stops short of the interface.
KEEP = 0.2


def _hat_bounds(s_I: float, w: np.ndarray, corners: np.ndarray, s_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the hat around s_I on every column: the pinned offsets (0, the station corners,
    s_max) around s_I where w = 0 (on and inside the hole circle), 0 and s_max where w = 1."""
    pinned = np.concatenate([[0.0, s_max], corners])
    c_lo, c_hi = pinned[pinned < s_I].max(), pinned[pinned > s_I].min()
    return (1 - w) * c_lo, (1 - w) * c_hi + w * s_max


def _reached(sigma: np.ndarray, s_I: float, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """σ clipped to keep the layers ordered (``KEEP``), and True where that left it unchanged."""
    target = np.clip(sigma, lo + KEEP * (s_I - lo), hi - KEEP * (hi - s_I))
    return target, np.isclose(target, sigma, rtol=0, atol=1e-12)


def _interface_offset(sigma: np.ndarray, beside: np.ndarray, on_wall: np.ndarray, corners: np.ndarray,
                      s_max: float, axial_mm: float) -> float | None:
    """s_I: the layer offset that becomes the material interface, the median of the offsets
    ``sigma`` the columns ``beside`` the hole would need, kept half an ``axial_mm`` from 0, from
    s_max and from every station corner (pinned layers); None when no such offset is left, or
    when the layer would reach the interface on less than :data:`INTERFACE_ON_WALL` of the
    columns ``on_wall`` (the hole circle, where the corners are pinned)."""
    target = float(np.median(sigma[beside]))
    pinned = np.concatenate([[0.0, s_max], corners])
    if not 0.5 * axial_mm < target < s_max - 0.5 * axial_mm:
        return None
    near = pinned[np.argmin(np.abs(pinned - target))]
    if abs(target - near) < 0.5 * axial_mm:
        target = near + np.copysign(0.5 * axial_mm, target - near)
    if np.abs(pinned - target).min() < 0.5 * axial_mm - 1e-12:
        return None
    lo, hi = _hat_bounds(target, np.zeros(int(on_wall.sum())), corners, s_max)
    reached = _reached(sigma[on_wall], target, lo, hi)[1].mean()
    if reached < INTERFACE_ON_WALL:
        log.warning("hole mesh: the material interface crosses a station's corner on the hole circle (followed on "
                    "%.0f %% of it); its cells take their material by centroid instead", 100 * reached)
        return None
    return target


def _conforming_offsets(s: np.ndarray, s_I: float, sigma: np.ndarray, w: np.ndarray,
                        corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-column offsets s'_j = s_j + δ φ(s_j) that carry the layer s_I to σ (the interface).

    φ is the hat function that is 1 at s_I and 0 outside [lo, hi] (:func:`_hat_bounds`): on the
    hole circle and inside it the station corners around s_I stay where they are, so every
    station's hole is still a union of cells; far from the hole the hat spans the whole column.
    δ = σ − s_I is clipped so σ stays :data:`KEEP` of the way inside [lo, hi] (the layers stay
    ordered and no thinner than ``KEEP`` of their nominal thickness); there the layer misses
    the interface.

    Returns the (n_columns, L) offsets and (n_columns,) True where the layer meets σ."""
    lo, hi = _hat_bounds(s_I, w, corners, s[-1])
    target, meets = _reached(sigma, s_I, lo, hi)
    up = (s[None, :] - lo[:, None]) / (s_I - lo)[:, None]
    down = (hi[:, None] - s[None, :]) / (hi - s_I)[:, None]
    hat = np.clip(np.minimum(up, down), 0.0, 1.0)
    return s[None, :] + (target - s_I)[:, None] * hat, meets


def hole_mesh(frame: HoleFrame, diameter_mm: float, point_angle_deg: float, submodel_radius_mm: float,
              tip_depths_mm, top, bottom, region=None, resolution: Resolution = Resolution(),
              interface=None) -> HoleMesh:
    """Mesh the bone around a drill axis, with the hole at every station as a union of cells.

    Parameters
    ----------
    frame : the hole's local frame (entry point o on the top surface, drill axis d)
    diameter_mm : drill diameter D = 2R [mm]
    point_angle_deg : drill point angle β [degrees]
    submodel_radius_mm : R_sub, radius of the local model around the axis [mm]
    tip_depths_mm : increasing drill-tip depths below o along d of the stations [mm]
    top : callable, (n, 2) local (x₁, x₂) → (n,) ζ of the bone's top surface [mm]
    bottom : callable, (n, 2) → ((n,) ζ of the column's bottom [mm], (n,) bool free surface)
    region : callable, (n, 3) global points → (n,) region codes (0: empty, the cell is dropped);
             default: all cortical
    resolution : :class:`Resolution`
    interface : callable, (n, 2) → (n,) ζ of a material interface below the top (the cortex's
                inner surface) that one layer follows on and outside the hole circle; None: none

    Returns
    -------
    :class:`HoleMesh`

    Examples
    --------
    >>> plate = hole_mesh(HoleFrame.along([0, 0, 0], [0, 0, 1]), 2.7, 90.0, 6.0, [2.0, 3.0],
    ...                   top=lambda xy: np.zeros(len(xy)),
    ...                   bottom=lambda xy: (np.full(len(xy), 2.5), np.ones(len(xy), bool)))
    >>> plate.n_stations
    2
    """
    R = diameter_mm / 2
    require(diameter_mm > 0 and 0 < point_angle_deg < 180, f"drill Ø{diameter_mm} mm, point angle "
                                                           f"{point_angle_deg}° is not a drill")
    cot = 1.0 / np.tan(np.radians(point_angle_deg) / 2)
    cone = R * cot
    tips = np.atleast_1d(np.asarray(tip_depths_mm, float))
    require(len(tips) >= 1 and np.all(tips > 0) and np.all(np.diff(tips) > 0),
            f"station tip depths must be positive and increasing, got {tips.tolist()}")
    corners = tips - cone
    sizes = resolution.scaled
    entry_rings = R + corners[corners < 0] / cot
    d2 = disk(R, submodel_radius_mm, sizes["n_wall"], sizes["wall_mm"], sizes["growth"], entry_rings)

    T = np.asarray(top(d2.xy), float)
    B, free = bottom(d2.xy)
    B, free = np.asarray(B, float), np.asarray(free, bool)
    require(T.shape == B.shape == free.shape == (len(d2.xy),) and np.all(np.isfinite(T)) and np.all(np.isfinite(B)),
            "the top and bottom callables must give one finite depth per column")
    require(np.all(B > T), f"{np.sum(B <= T)} columns have no bone (bottom not below top) within "
                           f"{submodel_radius_mm} mm of the drill axis")
    w = _blend(d2.radius, R)
    lift = w * (T - T[0])
    ahead = free[0] and tips.max() < B[0]  # bone ahead of the deepest tip on the axis (d2.xy[0])
    ligament = ((float(corners.max()), min(float(B[0]) - cone, float(corners.max()) + resolution.ligament_depth_mm))
                if ahead else None)
    s_max = float(np.max(B - lift))
    c = np.maximum(R - d2.radius, 0.0) * cot
    sigma = s_I = None
    if interface is not None:
        sigma = np.asarray(interface(d2.xy), float) - c - lift
        beside = (d2.radius >= R * (1 - 1e-9)) & (d2.radius <= 2 * R)
        s_I = _interface_offset(sigma, beside, d2.ring == d2.hole_ring, corners, s_max, sizes["axial_mm"])
    s = _layer_offsets(d2, cot, corners, s_max, sizes, ligament, s_I)
    S = np.broadcast_to(s, (len(d2.xy), len(s)))
    if s_I is not None:
        S, meets = _conforming_offsets(s, s_I, sigma, w, corners)
        log.info("hole mesh: the layer at offset %.2f mm follows the material interface on %d of %d columns",
                 s_I, meets.sum(), len(meets))
    Z = np.clip(S + (c + lift)[:, None], T[:, None], B[:, None])
    spacing = np.diff(S, axis=1)
    snap = resolution.snap
    inf = np.full((len(Z), 1), np.inf)
    below_top = Z - T[:, None] < snap * np.concatenate([inf, spacing], axis=1)
    above_bottom = B[:, None] - Z < snap * np.concatenate([spacing, inf], axis=1)
    below_top[:, 0] = above_bottom[:, -1] = True
    Z = np.where(below_top, T[:, None], np.where(above_bottom, B[:, None], Z))

    tol = 1e-9 * max(1.0, float(np.abs(Z).max()))
    new = np.concatenate([np.ones((len(Z), 1), bool), np.diff(Z, axis=1) > tol], axis=1)
    local_id = np.cumsum(new, axis=1) - 1
    per_column = local_id[:, -1] + 1
    start = np.concatenate([[0], np.cumsum(per_column)[:-1]])
    ids = start[:, None] + local_id
    column = np.repeat(np.arange(len(Z)), per_column)
    depth = Z[new]
    points = frame.to_global(np.column_stack([d2.xy[column], depth]))

    tri = d2.triangles
    L = len(s)
    lower = ids[tri][:, :, :-1].transpose(0, 2, 1).reshape(-1, 3)  # (triangle, layer) rows
    upper = ids[tri][:, :, 1:].transpose(0, 2, 1).reshape(-1, 3)
    cell_triangle = np.repeat(np.arange(len(tri)), L - 1)
    cell_layer = np.tile(np.arange(L - 1), len(tri))
    alive = (upper != lower).any(axis=1)
    prisms = np.column_stack([lower, upper])[alive]
    cell_triangle, cell_layer = cell_triangle[alive], cell_layer[alive]
    tets, owner = split_prisms(prisms)
    tets = orient(points, tets)
    volume = signed_volumes(points, tets)
    flat = volume <= 1e-12 * float(np.ptp(points, axis=0).max()) ** 3
    require(not flat.any(), f"the column mesh has {flat.sum()} flat tetrahedra; the top and bottom surfaces "
                            "vary too sharply between neighbouring columns for this resolution")

    in_hole = d2.in_hole[cell_triangle[owner]]
    after = s[cell_layer[owner] + 1]
    first = np.searchsorted(corners, after - 1e-9 * max(1.0, cone), side="left")
    station = np.where(in_hole & (first < len(corners)), first, -1)

    centroids = points[tets].mean(axis=1)
    codes = np.full(len(tets), CORTICAL, np.int8) if region is None else np.asarray(region(centroids)).astype(np.int8)
    require(codes.shape == (len(tets),), "the region callable must give one code per point")
    solid = codes != 0
    tets, station, in_hole, codes = tets[solid], station[solid], in_hole[solid], codes[solid]
    require(len(tets) > 0, "the region callable leaves no bone in the local model")

    used = np.unique(tets)
    renumber = np.full(len(points), -1)
    renumber[used] = np.arange(len(used))
    points, tets, column, depth = points[used], renumber[tets], column[used], depth[used]

    faces, _ = _boundary_faces(tets)
    on_top = np.abs(depth - T[column]) <= tol
    on_bottom = np.abs(depth - B[column]) <= tol
    lateral = d2.ring[column] == len(d2.ring_radii) - 1
    labels = np.full(len(faces), "void", dtype=object)
    all_of = lambda mask: mask[faces].all(axis=1)  # noqa: E731
    labels[all_of(on_bottom)] = "cut_bottom"
    labels[all_of(on_bottom) & all_of(free[column])] = "bottom_free"
    labels[all_of(on_top)] = "top"
    labels[all_of(lateral)] = "cut_lateral"
    face_sets = {name: faces[labels == name] for name in LABELS if name not in ("hole_wall", "hole_bottom")}

    mesh = TetMesh(points, tets, codes)
    result = HoleMesh(frame, R, float(point_angle_deg), float(submodel_radius_mm), resolution, mesh, station, tips,
                      face_sets, in_hole, column, T, s, d2, quality(mesh))
    log.info("hole mesh: %d points, %d tets, %d stations, minimum dihedral %.1f°", mesh.n_points, mesh.n_tets,
             len(tips), result.quality["min_dihedral_deg"])
    return result
