"""Anatomical frame of a femur surface: units, long axis, proximal end, anterior, side.

Detection, each step overridable from the case file (``geometry.units``, ``long_axis``,
``proximal_end``, ``anterior``, ``side``):

* units: an adult femur is 0.25-0.7 m long, so the extent along the principal axis tells
  metres, centimetres, inches or millimetres apart;
* long axis: the principal axis of largest variance of the area-weighted triangle centroids;
* proximal end: the femoral head sits on the neck, well off the shaft axis, while the
  condyles straddle it; the end whose last 6 % of length has its centroid further from the
  shaft line (fitted through the middle 40 %) is proximal;
* medial-lateral axis: the widest direction of the condyles (principal axis of the distal
  15 % cross-section), signed towards the head (medial);
* anterior: the condyles project posteriorly from the shaft line and the shaft bows
  anteriorly; both are measured and the sign with their (length-normalised) sum wins;
* side: in a right-handed frame, anterior × proximal points to the subject's right, which is
  medial for a left femur.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from femstudy.errors import UserError, require

UNIT_SCALE = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
#: Plausible femur lengths in each unit (an adult femur is 250-700 mm).
#: Smallest offset of the head's end from the shaft line, as a fraction of the length (a real
#: femur: 35-50 mm on 400-480 mm, about 0.1).
HEAD_OFFSET_MIN = 0.04
UNIT_RANGES = {"m": (0.2, 0.75), "in": (8.0, 24.0), "cm": (24.5, 75.0), "mm": (200.0, 750.0)}


@dataclass
class Frame:
    """Anatomical frame [mm] of a femur after unit conversion.

    up       : unit long axis, distal -> proximal
    anterior : unit, perpendicular to ``up``
    medial   : unit, perpendicular to both (towards the body's midline)
    top_mm   : largest coordinate along ``up`` (top of the head)
    length_mm: extent along ``up``
    """

    units: str
    scale_to_mm: float
    up: np.ndarray
    anterior: np.ndarray
    medial: np.ndarray
    side: str
    top_mm: float
    length_mm: float
    overridden: list[str] = field(default_factory=list)
    evidence: dict = field(default_factory=dict)

    def fraction(self, x: np.ndarray) -> np.ndarray:
        """Fraction of the length from the proximal end (0 = top of head, 1 = bottom of condyles)."""
        return (self.top_mm - np.asarray(x) @ self.up) / self.length_mm

    def height(self, fraction) -> float:
        """Coordinate along ``up`` of the level at ``fraction`` from the proximal end [mm]."""
        return self.top_mm - np.asarray(fraction) * self.length_mm

    def direction(self, name_or_vector) -> np.ndarray:
        """Unit vector of an anatomical direction name or of a given vector (normalised)."""
        named = {"anterior": self.anterior, "posterior": -self.anterior, "medial": self.medial,
                 "lateral": -self.medial, "proximal": self.up, "distal": -self.up}
        if isinstance(name_or_vector, str):
            return named[name_or_vector]
        v = np.asarray(name_or_vector, float)
        return v / np.linalg.norm(v)

    def as_dict(self) -> dict:
        d = asdict(self)
        for k in ("up", "anterior", "medial"):
            d[k] = [float(c) for c in d[k]]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Frame":
        d = dict(d)
        for k in ("up", "anterior", "medial"):
            d[k] = np.asarray(d[k], float)
        return cls(**d)


def detect_units(extent: float, requested: str) -> tuple[str, float, list[str]]:
    """Unit name and scale to mm for a femur whose raw length is ``extent``."""
    if requested != "auto":
        length_mm = extent * UNIT_SCALE[requested]
        lo, hi = UNIT_RANGES["mm"]
        if not lo <= length_mm <= hi:
            likely = [u for u, (a, b) in UNIT_RANGES.items() if a <= extent <= b]
            hint = f"; it looks like {likely[0]}: set geometry.units = \"{likely[0]}\" or \"auto\"" if likely else ""
            raise UserError(f"with geometry.units = \"{requested}\" the bone is {length_mm:.4g} mm long, not a femur "
                            f"(expected {lo:g}-{hi:g} mm){hint}")
        return requested, UNIT_SCALE[requested], ["units"]
    for unit, (lo, hi) in UNIT_RANGES.items():
        if lo <= extent <= hi:
            return unit, UNIT_SCALE[unit], []
    raise UserError(f"cannot tell the units of a femur {extent:.4g} long (expected about 0.45 m, 45 cm, "
                    "18 in or 450 mm); set geometry.units in the case file")


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def principal_axes(points: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted centroid and principal axes (rows, largest variance first)."""
    c = np.average(points, axis=0, weights=weights)
    d = points - c
    cov = (d * weights[:, None]).T @ d / weights.sum()
    w, v = np.linalg.eigh(cov)
    return c, v[:, ::-1].T


def _area_samples(points: np.ndarray, triangles: np.ndarray, per_extent: int = 80):
    """Centres and areas of the surface's triangles after subdividing any triangle longer
    than 1/``per_extent`` of the bone, so that every slice along the bone holds samples
    even on a coarse triangulation (a CAD export with long slivers, say)."""
    import pyvista as pv

    extent = float(np.ptp(points, axis=0).max())
    v = points[triangles]
    if np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2).max() > extent / per_extent:
        fine = pv.PolyData.from_regular_faces(points, triangles).subdivide_adaptive(max_edge_len=extent / per_extent)
        v = np.asarray(fine.points, float)[fine.regular_faces]
    return v.mean(axis=1), 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


def build_frame(points: np.ndarray, triangles: np.ndarray, geometry) -> tuple[Frame, np.ndarray]:
    """Detect the frame of a raw surface; returns the frame and the points converted to mm.

    ``geometry`` is the case's :class:`~femstudy.casefile.GeometrySpec`.
    """
    centres, areas = _area_samples(points, triangles)
    _, axes = principal_axes(centres, areas)
    overridden: list[str] = []
    axis = axes[0]
    if geometry.long_axis != "auto":
        axis = _unit(geometry.long_axis)
        overridden.append("long_axis")
    else:
        axis = axis * np.sign(axis[np.argmax(np.abs(axis))])
    proj = points @ axis
    units, scale, o = detect_units(float(proj.max() - proj.min()), geometry.units)
    overridden += o
    pts = points * scale
    centres = centres * scale
    areas = areas * scale ** 2
    h = centres @ axis
    lo, hi = float((pts @ axis).min()), float((pts @ axis).max())
    length = float(hi - lo)
    evidence: dict = {}

    # shaft line through centroids of the middle 40 %, as a function of height
    def centroid(sel):
        return np.average(centres[sel], axis=0, weights=areas[sel])

    t = (h - lo) / length
    mids = [centroid((t > a) & (t <= a + 0.05)) for a in np.arange(0.3, 0.7, 0.05)]
    mids = np.array(mids)
    A = np.column_stack([np.ones(len(mids)), mids @ axis])
    coef, *_ = np.linalg.lstsq(A, mids, rcond=None)

    def off_shaft(p):
        """Vector from the shaft line to p, perpendicular to the axis."""
        q = coef[0] + coef[1] * (p @ axis)
        d = p - q
        return d - (d @ axis) * axis

    end_plus, end_minus = centroid(t > 0.94), centroid(t < 0.06)
    off_plus, off_minus = np.linalg.norm(off_shaft(end_plus)), np.linalg.norm(off_shaft(end_minus))
    evidence["end_offsets_mm"] = {"+": round(float(off_plus), 1), "-": round(float(off_minus), 1)}
    if geometry.proximal_end != "auto":
        sign = 1.0 if geometry.proximal_end == "+" else -1.0
        overridden.append("proximal_end")
    else:
        sign = 1.0 if off_plus > off_minus else -1.0
    up = sign * axis
    # the femoral head sits 35-50 mm off the shaft line; demand a clear, one-sided offset
    if geometry.proximal_end == "auto" and (max(off_plus, off_minus) < HEAD_OFFSET_MIN * length
                                            or max(off_plus, off_minus) < 1.3 * min(off_plus, off_minus)):
        raise UserError(f"cannot tell which end of the bone is proximal: neither end is offset from the shaft "
                        f"like a femoral head (end offsets {off_plus:.1f} and {off_minus:.1f} mm); "
                        "set geometry.proximal_end (and check that the surface is a femur)")
    s = (hi - h) / length if sign > 0 else (h - lo) / length
    head_dir = off_shaft(end_plus if sign > 0 else end_minus)
    # medial-lateral: widest direction of the distal 15 %, signed towards the head
    sel = s > 0.85
    _, dax = principal_axes(centres[sel] - np.outer(centres[sel] @ up, up), areas[sel])
    ml = dax[0] - (dax[0] @ up) * up
    ml = _unit(ml)
    if ml @ head_dir < 0:
        ml = -ml
    cand = _unit(np.cross(up, ml))  # anterior if the bone is a left femur; the sign is tested next
    condyles = off_shaft(centroid((s > 0.85) & (s < 0.97))) @ cand
    bow_mid = off_shaft(centroid((s > 0.45) & (s < 0.55))) @ cand
    ends = 0.5 * (off_shaft(centroid((s > 0.25) & (s < 0.3))) + off_shaft(centroid((s > 0.72) & (s < 0.77)))) @ cand
    bow = bow_mid - ends
    score = (-condyles + bow) / length
    evidence.update(condyle_offset_mm=round(float(condyles), 1), shaft_bow_mm=round(float(bow), 1))
    anterior = cand if score > 0 else -cand
    if geometry.anterior != "auto":
        a = _unit(geometry.anterior)
        a = a - (a @ up) * up
        require(np.linalg.norm(a) > 1e-6, "geometry.anterior must not be parallel to the long axis")
        anterior = _unit(a)
        overridden.append("anterior")
    elif geometry.side != "auto":
        # a stated side fixes the sign of anterior, given the medial direction of the head
        anterior = _unit(np.cross(up, ml)) * (1 if geometry.side == "left" else -1)
    right = np.cross(anterior, up)
    side = "left" if right @ head_dir > 0 else "right"
    if geometry.side != "auto":
        if geometry.side != side:
            evidence["side_note"] = f"detected {side}, set to {geometry.side} by the case file"
        side = geometry.side
        overridden.append("side")
    medial = right if side == "left" else -right
    top = float((pts @ up).max())
    return Frame(units, scale, up, anterior, _unit(medial), side, top, length, overridden, evidence), pts
