"""Which end of a femur is which: the femoral head and the two condyles.

Each end (the last 20 % of the length at either end of the long axis) is searched for the
spherical cap covering the largest share of its sphere (:func:`~femstudy.meshing.spheres.find_sphere`,
radii 3-8 % of the length), then for a second one away from the first:

* a **femoral head** is a cap of radius 3.5-7 % of the length (18-28 mm on an adult femur
  of 400-480 mm) fitting within 5 % of its radius (rms) and covering at least 40 % of its
  sphere; on the femurs measured it covers 46-87 %, while the best cap at the knee covers
  15-39 % (docs/meshing.md);
* a **pair of condyles** is two caps of similar coverage (the smaller at least 60 % of the
  larger) side by side: centres within 3 % of the length of each other along the axis and
  3.5-20 % of it apart across it. At the hip the second cap (the greater trochanter, the
  neck) covers 26-39 % of what the head does, while condyles cover alike (78-103 %).

The proximal end is the one with a head whose coverage is at least 1.5 times the other
end's best; failing that, the end opposite the only pair of condyles. When the two cues
disagree, or neither decides, the ends are reported as ambiguous with what was measured.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femstudy.errors import UserError
from femstudy.meshing.spheres import SphereFit, find_sphere

END_SPAN = 0.2                      #: share of the length searched at each end
SEARCH_RADII = (0.03, 0.08)         #: radii searched, as fractions of the length
HEAD_RADII = (0.035, 0.07)          #: plausible head radii, as fractions of the length
HEAD_MAX_RMS = 0.05                 #: largest rms residual of a head, as a fraction of its radius
HEAD_MIN_COVERAGE = 0.40            #: smallest share of its sphere a head shows
HEAD_MARGIN = 1.5                   #: a head covers at least this many times the other end's best cap
LOBE_MIN_RATIO = 0.6                #: the smaller condyle covers at least this share of the larger
LOBE_MAX_AXIAL = 0.03               #: condyle centres at most this far apart along the axis (× length)
LOBE_ACROSS = (0.035, 0.2)          #: and this far apart across it (× length)
VOTE_CELL = 0.01                    #: voting bin, as a fraction of the length
SHELL_BAND = 0.06                   #: kept samples lie within this share of the radius from the sphere


@dataclass(frozen=True)
class EndShape:
    """The two best spherical caps at one end of the bone and what they amount to [mm].

    end      : "+" or "-", the end with the larger or smaller coordinate along the axis
    first    : best cap (largest coverage), or None if none was found
    second   : best cap among the samples off the first one's shell, or None
    head     : ``first`` is a plausible femoral head
    condyles : ``first`` and ``second`` form a pair of condyles
    """

    end: str
    first: SphereFit | None
    second: SphereFit | None
    head: bool
    condyles: bool

    def summary(self) -> dict:
        """Measured caps and verdicts as plain numbers (frame evidence)."""
        return {"best_cap_mm": self.first.summary() if self.first else None,
                "second_cap_mm": self.second.summary() if self.second else None,
                "femoral_head": self.head, "condyles": self.condyles}

    def describe(self) -> str:
        """A short phrase with the best cap's radius, residual and coverage."""
        if self.first is None:
            return f"{self.end} end: no spherical cap"
        f = self.first
        return f"{self.end} end: best cap radius {f.radius:.1f} mm, rms {f.rms:.2f} mm, {100 * f.coverage:.0f} % of its sphere"


def describe_end(centres: np.ndarray, normals: np.ndarray, areas: np.ndarray, axis: np.ndarray, end: str,
                 length: float) -> EndShape:
    """Search one end of the bone for a femoral head and a pair of condyles.

    Parameters
    ----------
    centres, normals, areas
        Surface samples [mm]: positions (n, 3), unit outward normals (n, 3), areas (n,).
    axis
        Unit long axis; ``end`` "+" is the end with the larger coordinate along it.
    length
        Extent of the bone along ``axis`` [mm].

    Returns
    -------
    EndShape

    Examples
    --------
    >>> from femstudy.meshing.builtin_femur import BUILTIN_STL
    >>> from femstudy.meshing.surface import read_surface, surface_samples
    >>> s = read_surface(BUILTIN_STL)
    >>> x, n, a = surface_samples(s.points, s.triangles)
    >>> describe_end(x, n, a, np.array([0, 0, 1.0]), "+", 455.0).head
    True
    """
    h = centres @ axis
    lo, hi = h.min(), h.max()
    sel = h > hi - END_SPAN * (hi - lo) if end == "+" else h < lo + END_SPAN * (hi - lo)
    x, n, a = centres[sel], normals[sel], areas[sel]
    radii = (SEARCH_RADII[0] * length, SEARCH_RADII[1] * length)
    first = find_sphere(x, n, a, radii, VOTE_CELL * length, band=SHELL_BAND)
    if first is None:
        return EndShape(end, None, None, False, False)
    off = np.linalg.norm(x - first.centre, axis=1) > first.radius * (1 + SHELL_BAND)
    second = find_sphere(x[off], n[off], a[off], radii, VOTE_CELL * length, band=SHELL_BAND)
    head = (HEAD_RADII[0] * length <= first.radius <= HEAD_RADII[1] * length
            and first.rms <= HEAD_MAX_RMS * first.radius and first.coverage >= HEAD_MIN_COVERAGE)
    condyles = False
    if second is not None:
        gap = second.centre - first.centre
        axial = abs(gap @ axis)
        across = np.linalg.norm(gap - (gap @ axis) * axis)
        condyles = bool(second.coverage >= LOBE_MIN_RATIO * first.coverage and axial <= LOBE_MAX_AXIAL * length
                        and LOBE_ACROSS[0] * length <= across <= LOBE_ACROSS[1] * length)
    return EndShape(end, first, second, bool(head), condyles)


def proximal_end(plus: EndShape, minus: EndShape) -> str:
    """"+" or "-": the end with the femoral head, or else the end opposite the condyles.

    Raises :class:`~femstudy.errors.UserError` with both ends' measurements when the
    head and the condyles disagree or neither decides.

    Examples
    --------
    >>> from femstudy.meshing.spheres import SphereFit
    >>> cap = lambda r, c: SphereFit(np.zeros(3), r, 0.3, c)
    >>> proximal_end(EndShape("+", cap(22, 0.3), cap(21, 0.28), False, True),
    ...              EndShape("-", cap(23, 0.8), cap(24, 0.2), True, False))
    '-'
    """
    def coverage(e: EndShape) -> float:
        return e.first.coverage if e.first is not None else 0.0

    by_head = None
    for this, other in ((plus, minus), (minus, plus)):
        if this.head and coverage(this) >= HEAD_MARGIN * coverage(other):
            by_head = this.end
    by_condyles = None
    if plus.condyles != minus.condyles:
        by_condyles = minus.end if plus.condyles else plus.end
    if by_head and by_condyles and by_head != by_condyles:
        problem = "the femoral head and the condyles point to opposite ends"
    elif by_head or by_condyles:
        return by_head or by_condyles
    elif plus.head or minus.head:
        problem = "both ends carry a similar spherical cap, so neither stands out as the femoral head"
    else:
        problem = "neither end carries a femoral head (a near-spherical cap) or a pair of condyles"
    raise UserError(f"cannot tell which end of the bone is proximal: {problem} ({plus.describe()}; {minus.describe()}); "
                    "set geometry.proximal_end (and check that the surface is a femur)")
