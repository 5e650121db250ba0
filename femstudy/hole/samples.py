"""Points at a given distance from a drilled hole's surface, for stress measures near the hole.

The hole at a station is the convex set {r ≤ R, ζ ≤ s + (R − r) cot(β/2)} (corner depth s,
cone length l = R cot(β/2)); the points at distance δ from it, in a half-plane through the
axis (coordinates r, ζ), form one curve:

* wall:   r = R + δ, from the highest top of the hole circle's columns down to ζ = s;
* corner: the arc of radius δ about the corner (R, s), from the wall normal (+r) to the cone
  normal (cos(β/2), sin(β/2));
* cone:   the cone moved by δ along its normal, from the corner arc to the tip arc;
* tip:    the arc of radius δ about the tip (0, s + l), from the cone normal to +ζ (the axis).

The curve is sampled every ``spacing_mm`` of arc length and swept about the axis with
⌈2π r / spacing⌉ (at least 8) points per circle of radius r (one on the axis). The default
spacing, 0.05 mm + δ/20 (0.075 mm at δ = 0.5 mm, 0.3 mm at δ = 5 mm), resolves the stress
field, whose length scales there are δ and the drill radius. Points outside the bone (above
the top, below the bottom, beyond R_sub) are not in the mesh; :func:`femstudy.hole.probe.point_probe`
reports them. Units: mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femstudy.errors import require

PARTS = ("wall", "corner", "cone", "tip")


@dataclass(frozen=True)
class OffsetSamples:
    """points (n, 3) [mm] at ``distance_mm`` from the hole surface; part (n,) index into :data:`PARTS`."""

    distance_mm: float
    spacing_mm: float
    points: np.ndarray
    part: np.ndarray

    def of(self, name: str) -> np.ndarray:
        """Mask of the points on one part of the curve."""
        return self.part == PARTS.index(name)


def _segment(a: np.ndarray, b: np.ndarray, spacing: float) -> np.ndarray:
    n = max(1, int(np.ceil(np.linalg.norm(b - a) / spacing)))
    return a + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a)


def _arc(centre: np.ndarray, radius: float, start: float, stop: float, spacing: float) -> np.ndarray:
    n = max(1, int(np.ceil(radius * abs(stop - start) / spacing)))
    phi = np.linspace(start, stop, n + 1)
    return centre + radius * np.column_stack([np.cos(phi), np.sin(phi)])


def offset_samples(station, distance_mm: float, spacing_mm: float | None = None) -> OffsetSamples:
    """Points at ``distance_mm`` from the hole surface (wall and cone) of a drilled station.

    Parameters
    ----------
    station : :class:`femstudy.hole.mesh.HoleStation` (index ≥ 0)
    distance_mm : δ > 0 [mm]
    spacing_mm : sampling step along the curve and around the axis [mm]; default 0.05 + δ/20

    Returns
    -------
    :class:`OffsetSamples`

    Example
    -------
    >>> samples = offset_samples(hole.at_station(2), 1.0)  # doctest: +SKIP
    >>> stress = point_probe(system, samples.points).stress(u)  # doctest: +SKIP
    """
    require(station.index >= 0, "offset samples need a drilled station (index ≥ 0)")
    require(distance_mm > 0, f"the distance from the hole must be positive, got {distance_mm} mm")
    delta = float(distance_mm)
    spacing = 0.05 + delta / 20 if spacing_mm is None else float(spacing_mm)
    require(spacing > 0, f"the sample spacing must be positive, got {spacing} mm")
    hole = station.hole
    R, l, s = hole.radius_mm, hole.cone_length_mm, station.corner_depth_mm
    half = np.radians(hole.point_angle_deg) / 2
    top = hole.hole_top_mm

    pieces, parts = [], []
    if s > top:
        pieces.append(_segment(np.array([R + delta, top]), np.array([R + delta, s]), spacing)[:-1])
        parts.append(0)
    corner = np.array([R, s])
    pieces.append(_arc(corner, delta, 0.0, half, spacing)[:-1])
    parts.append(1)
    normal = np.array([np.cos(half), np.sin(half)])
    tip = np.array([0.0, s + l])
    pieces.append(_segment(corner + delta * normal, tip + delta * normal, spacing)[:-1])
    parts.append(2)
    pieces.append(_arc(tip, delta, half, np.pi / 2, spacing))
    parts.append(3)
    curve = np.concatenate(pieces)
    curve_part = np.concatenate([np.full(len(p), k) for p, k in zip(pieces, parts)])

    local, part = [], []
    for (r, zeta), k in zip(curve, curve_part):
        n = 1 if r < 1e-12 else max(8, int(np.ceil(2 * np.pi * r / spacing)))
        theta = 2 * np.pi * np.arange(n) / n
        local.append(np.column_stack([r * np.cos(theta), r * np.sin(theta), np.full(n, zeta)]))
        part.append(np.full(n, k))
    return OffsetSamples(delta, spacing, hole.frame.to_global(np.concatenate(local)), np.concatenate(part))


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances of 2-D points p (n, 2) from the segment a–b."""
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def hole_distance(station, points: np.ndarray) -> np.ndarray:
    """Distance [mm] of each point from the hole of ``station`` (0 inside it).

    In a half-plane through the axis (r, ζ) the hole is {r ≤ R, ζ ≤ s + (R − r) cot(β/2)}; a
    point outside it is nearest to the wall line r = R above the corner (R, s) or to the cone
    segment from the corner to the tip (0, s + l) (module docstring).

    Parameters
    ----------
    station : :class:`femstudy.hole.mesh.HoleStation` (index ≥ 0)
    points : (n, 3) points [mm]

    Returns
    -------
    (n,) distances [mm]

    Example
    -------
    >>> far = hole_distance(station, quadrature_points) > 2.0  # doctest: +SKIP
    """
    require(station.index >= 0, "the distance from the hole needs a drilled station (index ≥ 0)")
    hole = station.hole
    R, l, s = hole.radius_mm, hole.cone_length_mm, station.corner_depth_mm
    half = np.radians(hole.point_angle_deg) / 2
    local = hole.frame.to_local(np.atleast_2d(np.asarray(points, float)))
    rz = np.column_stack([np.hypot(local[:, 0], local[:, 1]), local[:, 2]])
    inside = (rz[:, 0] <= R) & ((rz[:, 0] - R) * np.cos(half) + (rz[:, 1] - s) * np.sin(half) <= 0)
    corner, tip = np.array([R, s]), np.array([0.0, s + l])
    above = np.array([R, min(s, float(rz[:, 1].min())) - 1.0])  # the wall reaches above every point
    distance = np.minimum(_segment_distance(rz, above, corner), _segment_distance(rz, corner, tip))
    return np.where(inside, 0.0, distance)
