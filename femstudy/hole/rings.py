"""The 2-D triangulation of a disk around a drill axis, conforming to the hole circle.

The disk r ≤ R_sub (in the plane ⟂ the drill axis, coordinates along e1, e2) is covered by
concentric rings of vertices. One ring lies exactly on the hole circle r = R_hole; outside
it the ring spacing grows from ``wall_mm`` by about ``growth`` per ring up to R_sub, inside
it the rings run the same way down to a vertex on the axis. Every ring has its vertices at
the angles π/n_wall + 2πk/n (n its vertex count): half a step off e1, so the directions
along ±e1 and ±e2 cross the hole circle mid-way between vertices, where the faceted wall is
flat (a vertex of the inscribed polygon is a slightly re-entrant corner of the bone, whose
stress converges slowly). A ring may carry half the
vertices of its neighbour (halving where it brings the elements closer to equal sides), so
the strips between rings are either quadrilaterals cut in two along alternating diagonals
or a transition of three triangles per coarse segment; the innermost ring is joined to
the axis vertex by a fan.

Units: mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femstudy.errors import require

#: Samples per interval of the numerical size integral in :func:`graded_points`.
_SAMPLES = 400


def graded_points(fixed: np.ndarray, size) -> np.ndarray:
    """Points through every value of ``fixed`` (sorted, distinct) whose spacing follows the
    size function ``size(s) -> h`` [mm]: between neighbouring fixed points a and b the
    n = max(1, round(∫ ds/h)) intervals are equal steps of ∫ ds/h, so each has length ≈ h.

    Parameters
    ----------
    fixed : (k,) sorted positions that must be points [mm]
    size : vectorised callable giving the wanted spacing at a position [mm]

    Returns
    -------
    (m,) sorted positions, ``fixed`` among them.

    Examples
    --------
    >>> graded_points(np.array([0.0, 1.0]), lambda s: np.full_like(s, 0.25))
    array([0.  , 0.25, 0.5 , 0.75, 1.  ])
    """
    fixed = np.asarray(fixed, float)
    require(len(fixed) >= 1 and np.all(np.diff(fixed) > 0), "graded points need sorted, distinct fixed points")
    out = [fixed[:1]]
    for a, b in zip(fixed[:-1], fixed[1:]):
        s = np.linspace(a, b, _SAMPLES + 1)
        inverse = 1.0 / np.asarray(size(s), float)
        cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (inverse[1:] + inverse[:-1]) * np.diff(s))])
        n = max(1, int(round(cumulative[-1])))
        inner = np.interp(np.arange(1, n) * cumulative[-1] / n, cumulative, s)
        out += [inner, [b]]
    return np.concatenate(out)


@dataclass(frozen=True)
class Disk:
    """A triangulated disk around the axis.

    xy             : (n, 2) vertex coordinates along e1, e2 [mm]
    radius         : (n,) the ring radius of every vertex (exact, not recomputed) [mm]
    ring           : (n,) ring index of every vertex (0 on the axis, increasing outwards)
    triangles      : (m, 3) vertex indices, counter-clockwise seen from above (against d)
    ring_radii     : (k,) radius of every ring [mm]
    ring_counts    : (k,) vertices on every ring (1 on the axis)
    hole_ring      : index of the ring on the hole circle
    """

    xy: np.ndarray
    radius: np.ndarray
    ring: np.ndarray
    triangles: np.ndarray
    ring_radii: np.ndarray
    ring_counts: np.ndarray
    hole_ring: int

    @property
    def in_hole(self) -> np.ndarray:
        """(m,) True for triangles inside the hole circle (every vertex on or inside it)."""
        return (self.ring[self.triangles] <= self.hole_ring).all(axis=1)


def _counts(radii: np.ndarray, n_wall: int, hole_ring: int, min_count: int = 4) -> np.ndarray:
    """Vertices per ring: n_wall on the hole circle; moving away from it a ring takes half
    its neighbour's count when that brings its arc length closer (in ratio) to the local
    ring spacing. The axis ring has one vertex."""
    spacing = np.gradient(radii)
    counts = np.zeros(len(radii), dtype=int)
    counts[hole_ring] = n_wall
    for order in (range(hole_ring + 1, len(radii)), range(hole_ring - 1, 0, -1)):
        previous = hole_ring
        for i in order:
            n = counts[previous]
            if n % 2 == 0 and n // 2 >= min_count:
                now = abs(np.log(2 * np.pi * radii[i] / n / spacing[i]))
                halved = abs(np.log(4 * np.pi * radii[i] / n / spacing[i]))
                n = n // 2 if halved < now else n
            counts[i] = n
            previous = i
    counts[0] = 1
    return counts


def _strip(inner: np.ndarray, outer: np.ndarray) -> np.ndarray:
    """Triangles between two rings of vertex indices (counts equal, or outer = inner / 2,
    or inner = outer / 2), in either orientation."""
    ni, no = len(inner), len(outer)
    if ni == no:
        k = np.arange(ni)
        a, b, c, e = inner[k], inner[(k + 1) % ni], outer[(k + 1) % no], outer[k]
        even = (k % 2 == 0)[:, None]
        first = np.where(even, np.column_stack([a, b, c]), np.column_stack([a, b, e]))
        second = np.where(even, np.column_stack([a, c, e]), np.column_stack([b, c, e]))
        return np.concatenate([first, second])
    k = np.arange(min(ni, no))
    if no * 2 == ni:  # coarse outer ring
        f0, f1, f2 = inner[2 * k], inner[2 * k + 1], inner[(2 * k + 2) % ni]
        c0, c1 = outer[k], outer[(k + 1) % no]
        return np.concatenate([np.column_stack([f0, f1, c0]), np.column_stack([f1, c1, c0]),
                               np.column_stack([f1, f2, c1])])
    require(ni * 2 == no, f"rings of {ni} and {no} vertices cannot be joined")
    f0, f1, f2 = outer[2 * k], outer[2 * k + 1], outer[(2 * k + 2) % no]
    c0, c1 = inner[k], inner[(k + 1) % ni]
    return np.concatenate([np.column_stack([c0, f1, f0]), np.column_stack([c0, c1, f1]),
                           np.column_stack([c1, f2, f1])])


def disk(hole_radius_mm: float, outer_radius_mm: float, n_wall: int, wall_mm: float, growth: float,
         inner_radii_mm=()) -> Disk:
    """Triangulate the disk r ≤ ``outer_radius_mm`` with a ring on r = ``hole_radius_mm``.

    Parameters
    ----------
    hole_radius_mm : R_hole, the drill radius [mm]
    outer_radius_mm : R_sub, the disk's radius [mm]
    n_wall : vertices on the hole circle, a multiple of 4 (so 0°, 90°, ... are mid-way between two)
    wall_mm : ring spacing at the hole circle and inside it [mm]
    growth : outside the circle the spacing grows as wall_mm + (growth − 1)·(r − R_hole)
    inner_radii_mm : further radii inside the hole that must be rings [mm]

    Returns
    -------
    :class:`Disk`

    Examples
    --------
    >>> d = disk(1.35, 8.0, 32, 0.2, 1.25)
    >>> bool(np.isclose(d.ring_radii[d.hole_ring], 1.35))
    True
    """
    R, R_sub = float(hole_radius_mm), float(outer_radius_mm)
    require(0 < R < R_sub, f"the submodel radius {R_sub} mm must exceed the hole radius {R} mm")
    require(n_wall >= 8 and n_wall % 4 == 0, f"the hole circle needs a multiple of 4 vertices (≥ 8), got {n_wall}")
    require(wall_mm > 0 and growth >= 1, f"ring spacing {wall_mm} mm and growth {growth} must be positive and ≥ 1")

    def size(r):
        return wall_mm + (growth - 1.0) * np.maximum(r - R, 0.0)

    extra = np.asarray(inner_radii_mm, float)
    require(np.all((extra > 0) & (extra < R)), "extra ring radii must lie strictly inside the hole")
    inside = graded_points(np.unique(np.concatenate([[0.0, R], extra])), size)
    outside = graded_points(np.array([R, R_sub]), size)
    radii = np.concatenate([inside, outside[1:]])
    hole_ring = len(inside) - 1
    counts = _counts(radii, n_wall, hole_ring)

    start = np.concatenate([[0], np.cumsum(counts)])
    rings = [np.arange(start[i], start[i + 1]) for i in range(len(radii))]
    angle = np.pi / n_wall + np.concatenate([2 * np.pi * np.arange(n) / n for n in counts])
    radius = np.repeat(radii, counts)
    xy = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    n1 = counts[1]
    fan = np.column_stack([np.zeros(n1, int), rings[1], np.roll(rings[1], -1)])
    strips = [_strip(rings[i], rings[i + 1]) for i in range(1, len(radii) - 1)]
    triangles = np.concatenate([fan] + strips)
    corner = xy[triangles]
    u, v = corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]
    clockwise = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] < 0
    triangles[clockwise] = triangles[clockwise][:, ::-1]
    return Disk(xy, radius, np.repeat(np.arange(len(radii)), counts), triangles, radii, counts, hole_ring)
