"""Anatomical frame of a femur surface: units, long axis, proximal end, anterior, side.

Detection works on a femur in any pose (a CT scanner's frame, say), mirrored or not, in mm,
cm, m or inches; each step can be overridden from the case file (``geometry.units``,
``long_axis``, ``proximal_end``, ``anterior``, ``side``):

* long axis: the principal axis of largest variance of the area-weighted triangle centroids;
* units: an adult femur is 0.25-0.7 m long, so the extent along the long axis tells
  metres, centimetres, inches or millimetres apart;
* proximal end: the end carrying the femoral head, a near-spherical cap, or else the end
  opposite the pair of condyles (:mod:`femstudy.meshing.bone_ends`);
* medial-lateral axis: the widest direction of the condyles (principal axis of the distal
  15 % cross-section), signed towards the head's centre (medial);
* anterior: the condyles project posteriorly from the shaft line and the shaft bows
  anteriorly; both are measured and the sign with their (length-normalised) sum wins;
* side: in a right-handed frame, anterior × proximal points to the subject's right, which is
  medial for a left femur.

A step that cannot decide raises :class:`~femstudy.errors.UserError` with what it measured.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from femstudy.errors import UserError, require
from femstudy.meshing import bone_ends
from femstudy.meshing.surface import surface_samples
from femstudy.meshing.units import UNIT_RANGES, UNIT_SCALE

log = logging.getLogger(__name__)

#: Smallest |condyle offset − shaft bow| that tells anterior from posterior, as a fraction of
#: the length (the built-in femur: 0.031; nine real femurs: 0.055-0.075, docs/meshing.md).
ANTERIOR_MIN_SCORE = 0.01


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
    evidence: dict[str, Any] = field(default_factory=dict)

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


def units_evidence(extent: float, unit: str, requested: str) -> dict:
    """Why ``unit`` was taken for a femur ``extent`` long in the file's own units: its length under
    every unit femstudy knows, and which of them put it in the range of adult femurs."""
    lengths = {u: round(extent * UNIT_SCALE[u], 1) for u in UNIT_SCALE}
    fits = [u for u, (lo, hi) in UNIT_RANGES.items() if lo <= extent <= hi]
    why = (f"set in the case file (geometry.units = \"{requested}\")" if requested != "auto" else
           f"the surface is {extent:.4g} long in its own units; only {unit} makes it a femur "
           f"({UNIT_RANGES['mm'][0]:g}-{UNIT_RANGES['mm'][1]:g} mm)")
    return {"raw_length": float(extent), "length_mm_if": lengths, "units_that_fit": fits, "why": why}


def detect_units(extent: float, requested: str) -> tuple[str, float, list[str]]:
    """Unit name and scale to mm for a femur whose raw length is ``extent``; a unit other than mm
    found automatically is announced in one progress line that shows the length under every unit
    (report.md and summary.json say the units and why); a warning would be a second message
    beside a user error found later in the same run."""
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
            if unit != "mm":
                lengths = ", ".join(f"{extent * UNIT_SCALE[u]:.4g} mm as {u}" for u in UNIT_SCALE)
                log.info("the surface is %.4g long in its own units, read as %s (%s); set geometry.units if it "
                            "is not in %s", extent, unit, lengths, unit)
            return unit, UNIT_SCALE[unit], []
    lengths = ", ".join(f"{extent * UNIT_SCALE[u]:.4g} mm as {u}" for u in UNIT_SCALE)
    raise UserError(f"cannot tell the units of the surface: it is {extent:.4g} long in its own units ({lengths}), "
                    f"and no unit makes it an adult femur ({UNIT_RANGES['mm'][0]:g}-{UNIT_RANGES['mm'][1]:g} mm); "
                    "set geometry.units in the case file")


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


def build_frame(points: np.ndarray, triangles: np.ndarray, geometry) -> tuple[Frame, np.ndarray]:
    """Detect the frame of a raw surface; returns the frame and the points converted to mm.

    Parameters
    ----------
    points, triangles
        The surface in the file's units: (n, 3) coordinates, (m, 3) vertex indices.
    geometry
        The case's :class:`~femstudy.casefile.GeometrySpec` (its overrides are honoured).

    Returns
    -------
    (Frame, points in mm)

    Examples
    --------
    >>> from femstudy.casefile import GeometrySpec
    >>> from femstudy.meshing.builtin_femur import BUILTIN_STL
    >>> from femstudy.meshing.surface import read_surface
    >>> s = read_surface(BUILTIN_STL)
    >>> frame, _ = build_frame(s.points, s.triangles, GeometrySpec())
    >>> frame.side, frame.units, [round(float(c)) for c in frame.up]
    ('left', 'mm', [0, 0, 1])
    """
    centres, normals, areas = surface_samples(points, triangles)
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
    units_found = units_evidence(float(proj.max() - proj.min()), units, geometry.units)
    pts = points * scale
    centres = centres * scale
    areas = areas * scale ** 2
    h = centres @ axis
    lo, hi = float((pts @ axis).min()), float((pts @ axis).max())
    length = float(hi - lo)

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

    ends = {e: bone_ends.describe_end(centres, normals, areas, axis, e, length) for e in "+-"}
    evidence: dict = {"units": units_found, "ends": {e: shape.summary() for e, shape in ends.items()}}
    if geometry.proximal_end != "auto":
        sign = 1.0 if geometry.proximal_end == "+" else -1.0
        overridden.append("proximal_end")
    else:
        sign = 1.0 if bone_ends.proximal_end(ends["+"], ends["-"]) == "+" else -1.0
    up = sign * axis
    evidence["proximal_end"] = "+" if sign > 0 else "-"
    s = (hi - h) / length if sign > 0 else (h - lo) / length
    top_end = ends["+" if sign > 0 else "-"]
    # medial: towards the head's centre, or the centroid of the top 6 % when no head was found
    head_centre = top_end.first.centre if top_end.head else centroid(s < 0.06)
    head_dir = off_shaft(head_centre)
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
    ends_bow = 0.5 * (off_shaft(centroid((s > 0.25) & (s < 0.3))) + off_shaft(centroid((s > 0.72) & (s < 0.77)))) @ cand
    bow = bow_mid - ends_bow
    score = (-condyles + bow) / length
    evidence.update(head_offset_mm=round(float(np.linalg.norm(head_dir)), 1),
                    condyle_offset_mm=round(float(condyles), 1), shaft_bow_mm=round(float(bow), 1))
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
    elif abs(score) < ANTERIOR_MIN_SCORE:
        raise UserError(f"cannot tell anterior from posterior: in the sagittal plane the condyles lie "
                        f"{abs(condyles):.1f} mm off the shaft line and the shaft bows {abs(bow):.1f} mm (on the femurs "
                        "measured the condyles lie 10-26 mm behind it and the shaft bows 4-6 mm forwards); set "
                        "geometry.side or geometry.anterior")
    right = np.cross(anterior, up)
    side = "left" if right @ head_dir > 0 else "right"
    head_along_ml = float(head_dir @ (right if side == "left" else -right))
    evidence["head_forward_angle_deg"] = round(float(np.degrees(np.arctan2(head_dir @ anterior, head_along_ml))), 1)
    if geometry.side != "auto":
        if geometry.side != side:
            evidence["side_note"] = f"detected {side}, set to {geometry.side} by the case file"
        side = geometry.side
        overridden.append("side")
    medial = right if side == "left" else -right
    top = float((pts @ up).max())
    return Frame(units, scale, up, anterior, _unit(medial), side, top, length, overridden, evidence), pts
