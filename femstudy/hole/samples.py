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
from typing import TYPE_CHECKING

import numpy as np

from femstudy.errors import require

if TYPE_CHECKING:
    from femstudy.hole.frame import HoleFrame

PARTS = ("wall", "corner", "cone", "tip")


@dataclass(frozen=True)
class OffsetCurve:
    """The curve at δ from the hole in a half-plane through its axis, by arc length t [mm].

    Pieces in order (wall, corner, cone, tip: :data:`PARTS`); ``breaks`` (5,) are the arc
    lengths where they start and the curve ends. A straight piece runs from ``a`` to ``b``; an
    arc has its centre in ``a`` and its radius, first and last angle in ``b``.
    """

    breaks: np.ndarray
    a: np.ndarray
    b: np.ndarray
    straight: np.ndarray

    def part(self, t: np.ndarray) -> np.ndarray:
        """Index into :data:`PARTS` of the piece holding each arc length t."""
        return np.clip(np.searchsorted(self.breaks, t, side="right") - 1, 0, len(PARTS) - 1)

    def rz(self, t: np.ndarray) -> np.ndarray:
        """(n, 2) points (r, ζ) [mm] at arc lengths t (n,)."""
        t = np.asarray(t, float)
        k = self.part(t)
        u = np.divide(t - self.breaks[k], self.breaks[k + 1] - self.breaks[k],
                      out=np.zeros_like(t), where=self.breaks[k + 1] > self.breaks[k])
        a, b = self.a[k], self.b[k]
        line = a + u[:, None] * (b - a)
        phi = b[:, 1] + u * (b[:, 2] - b[:, 1])
        arc = a[:, :2] + b[:, :1] * np.column_stack([np.cos(phi), np.sin(phi)])
        return np.where(self.straight[k][:, None], line[:, :2], arc)


def offset_curve(station, distance_mm: float) -> OffsetCurve:
    """The curve at ``distance_mm`` from the hole of a drilled station (module docstring)."""
    hole = station.hole
    R, l, s, delta = hole.radius_mm, hole.cone_length_mm, station.corner_depth_mm, float(distance_mm)
    half = np.radians(hole.point_angle_deg) / 2
    top = min(hole.hole_top_mm, s)
    normal = np.array([np.cos(half), np.sin(half)])
    corner, tip = np.array([R, s]), np.array([0.0, s + l])
    a = np.array([[R + delta, top, 0.0], [R, s, 0.0], [*(corner + delta * normal), 0.0], [0.0, s + l, 0.0]])
    b = np.array([[R + delta, s, 0.0], [delta, 0.0, half], [*(tip + delta * normal), 0.0], [delta, half, np.pi / 2]])
    lengths = [s - top, delta * half, l / np.sin(half), delta * (np.pi / 2 - half)]
    return OffsetCurve(np.concatenate([[0.0], np.cumsum(lengths)]), a, b, np.array([True, False, True, False]))


def _swept(curve: OffsetCurve, frame, t: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(n, 3) global points [mm] of the curve at arc lengths t swept to azimuths θ about the frame's axis."""
    rz = curve.rz(t)
    return frame.to_global(np.column_stack([rz[:, 0] * np.cos(theta), rz[:, 0] * np.sin(theta), rz[:, 1]]))


@dataclass(frozen=True)
class OffsetSamples:
    """points (n, 3) [mm] at ``distance_mm`` from the hole surface; part (n,) index into
    :data:`PARTS`; each point's arc length ``t`` [mm] along ``curve`` and azimuth ``theta``
    [rad] about the axis of ``frame``."""

    distance_mm: float
    spacing_mm: float
    points: np.ndarray
    part: np.ndarray
    t: np.ndarray
    theta: np.ndarray
    curve: OffsetCurve
    frame: HoleFrame

    def of(self, name: str) -> np.ndarray:
        """Mask of the points on one part of the curve."""
        return self.part == PARTS.index(name)

    def at(self, t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """(n, 3) global points [mm] at arc lengths t and azimuths θ."""
        return _swept(self.curve, self.frame, t, theta)

    def with_boundary_points(self, label, steps: int = 12) -> OffsetSamples:
        """These samples and, on the azimuth of each, the points where the curve leaves the bone
        or passes from one material into another.

        Between a sample (t_i, θ) and a neighbouring station of the curve (t_i±1, θ) with
        another label, one of the two in the bone, the crossing is bisected ``steps`` times in t
        (to spacing/2^steps) and its bone end added, or both ends where both are in the bone (a
        material interface): a measure's maximum on the bone's own surface (the canal under the
        tip, the entry surface) or on either side of the cortex's inner surface (where the stress
        jumps) is then sampled there, not at the last sample before it, which would move with
        the mesh of that surface.

        Parameters
        ----------
        label : callable, (n, 3) points → (n,) int, the region of each point, −1 outside the bone
        steps : bisections per crossing
        """
        knots = np.unique(self.t)
        i = np.searchsorted(knots, self.t)
        here = label(self.points)
        lo, hi, theta, side = [], [], [], []
        for step in (-1, 1):
            has = (i + step >= 0) & (i + step < len(knots))
            t_other = knots[np.clip(i + step, 0, len(knots) - 1)]
            there = here.copy()
            there[has] = label(self.at(t_other[has], self.theta[has]))
            cross = has & (here != there) & ((here >= 0) | (there >= 0))
            lo.append(np.where(here >= 0, self.t, t_other)[cross])  # a bone end
            hi.append(np.where(here >= 0, t_other, self.t)[cross])
            theta.append(self.theta[cross])
            side.append(np.where((here < 0) | (there < 0), -1, here)[cross])  # −1: leaving the bone
        lo, hi, theta, side = map(np.concatenate, (lo, hi, theta, side))
        for _ in range(steps):
            mid = (lo + hi) / 2
            at = label(self.at(mid, theta))
            same = np.where(side < 0, at >= 0, at == side)
            lo, hi = np.where(same, mid, lo), np.where(same, hi, mid)
        interface = side >= 0  # both ends are in the bone: keep the far side's too
        lo, theta = np.concatenate([lo, hi[interface]]), np.concatenate([theta, theta[interface]])
        return OffsetSamples(self.distance_mm, self.spacing_mm, np.concatenate([self.points, self.at(lo, theta)]),
                             np.concatenate([self.part, self.curve.part(lo)]), np.concatenate([self.t, lo]),
                             np.concatenate([self.theta, theta]), self.curve, self.frame)


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

    Examples
    --------
    >>> samples = offset_samples(hole.at_station(2), 1.0)  # doctest: +SKIP
    >>> stress = point_probe(system, samples.points).stress(u)  # doctest: +SKIP
    """
    require(station.index >= 0, "offset samples need a drilled station (index ≥ 0)")
    require(distance_mm > 0, f"the distance from the hole must be positive, got {distance_mm} mm")
    delta = float(distance_mm)
    spacing = 0.05 + delta / 20 if spacing_mm is None else float(spacing_mm)
    require(spacing > 0, f"the sample spacing must be positive, got {spacing} mm")
    curve = offset_curve(station, delta)
    t = [np.linspace(t0, t1, max(1, int(np.ceil((t1 - t0) / spacing))) + 1)[:-1]
         for t0, t1 in zip(curve.breaks[:-1], curve.breaks[1:]) if t1 > t0]
    t = np.concatenate(t + [curve.breaks[-1:]])
    r = curve.rz(t)[:, 0]
    count = np.where(r < 1e-12, 1, np.maximum(8, np.ceil(2 * np.pi * r / spacing).astype(int)))
    t_points = np.repeat(t, count)
    theta = np.concatenate([2 * np.pi * np.arange(n) / n for n in count])
    frame = station.hole.frame
    return OffsetSamples(delta, spacing, _swept(curve, frame, t_points, theta), curve.part(t_points), t_points, theta,
                         curve, frame)


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

    Examples
    --------
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
