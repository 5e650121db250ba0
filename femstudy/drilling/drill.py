"""Twist-drill geometry used by the cutting and chip-evacuation models (units: mm, degrees).

Defaults are the 2.7 mm, 90° surgical twist drill of the reference thesis (§4.1.3,
Appendix A). The wall contact length ``l_w`` is not legible in the thesis; the default is
derived from the thesis's own numbers, see :func:`wall_length_from_growth_exponent` and
``docs/load-models.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from femstudy import thesis
from femstudy.errors import require

#: l_w [mm] from Appendix B's mean growth exponent (p = 0.469324 at f = 1.5 mm/s,
#: N = 1500 rpm) and the bovine power law computed from Table 5-1; see
#: :func:`wall_length_from_growth_exponent` (a test recomputes it).
DERIVED_WALL_LENGTH_MM = 2.130


@dataclass(frozen=True)
class Drill:
    """Geometry of a two-flute twist drill.

    Attributes
    ----------
    diameter_mm : D, drill diameter.
    point_angle_deg : β, full point angle, in (0°, 180°).
    face_mm, heel_mm, root_mm, wall_mm : flute contact lengths l_f, l_h, l_r, l_w (Fig 3-8).
    flute_area_mm2 : S, flute cross-section (Eq A.2).
    face_angle_deg : θ, angle between flute face and the plane across the flute (Eq A.3).
    eta : η, ratio of lateral to axial chip pressure (≈ Poisson ratio of cortical bone).
    flutes : number of flutes (cutting lips), 2 for a twist drill.
    """

    diameter_mm: float = thesis.DRILL_DIAMETER_MM
    point_angle_deg: float = thesis.DRILL_POINT_ANGLE_DEG
    face_mm: float = 1.16
    heel_mm: float = 1.16
    root_mm: float = 0.29
    wall_mm: float = DERIVED_WALL_LENGTH_MM
    flute_area_mm2: float = 1.46
    face_angle_deg: float = 26.7
    eta: float = 0.4
    flutes: int = 2

    def __post_init__(self) -> None:
        require(math.isfinite(self.diameter_mm) and self.diameter_mm > 0,
                f"drill diameter must be a positive length in mm, got {self.diameter_mm}")
        require(math.isfinite(self.point_angle_deg) and 0 < self.point_angle_deg < 180,
                f"drill point angle must lie strictly between 0 and 180 degrees, "
                f"got {self.point_angle_deg}")
        tangent = math.tan(self.half_angle_rad)  # 0 for an angle whose radians underflow
        require(tangent > 0 and math.isfinite(self.radius_mm / tangent),
                f"drill point angle {self.point_angle_deg} degrees is too small: its tip cone would be "
                f"infinitely long")
        for name in ("face_mm", "heel_mm", "root_mm", "wall_mm", "flute_area_mm2"):
            value = getattr(self, name)
            require(math.isfinite(value) and value > 0,
                    f"drill {name} must be positive, got {value}")
        require(0 < self.face_angle_deg < 90,
                f"drill face_angle_deg must lie in (0, 90), got {self.face_angle_deg}")
        require(0 < self.eta <= 1, f"drill eta must lie in (0, 1], got {self.eta}")
        require(self.flutes >= 1, f"a drill has at least one flute, got {self.flutes}")

    @property
    def radius_mm(self) -> float:
        """R = D/2 [mm]."""
        return self.diameter_mm / 2

    @property
    def half_angle_rad(self) -> float:
        """β/2 [rad]."""
        return math.radians(self.point_angle_deg) / 2

    @property
    def cone_length_mm(self) -> float:
        """Tip cone length l = (D/2) / tan(β/2) [mm] (Eq A.1; 1.35 mm for the default)."""
        return self.radius_mm / math.tan(self.half_angle_rad)

    @property
    def flute_length_sum_mm(self) -> float:
        """l_f + l_h + l_r [mm], the flute contact lengths that carry μ_f alone."""
        return self.face_mm + self.heel_mm + self.root_mm

    def flute_passing_hz(self, spindle_rpm: float) -> float:
        """Frequency at which cutting lips pass a point of the hole bottom: flutes · N/60 [Hz]."""
        return self.flutes * spindle_rpm / 60.0

    def with_(self, **changes) -> "Drill":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)


def feed_per_revolution(feed_mm_s: float, spindle_rpm: float) -> float:
    """Feed per revolution a = f·60/N [mm/rev] for feed f [mm/s] and spindle speed N [rpm]."""
    require(math.isfinite(feed_mm_s) and feed_mm_s > 0,
            f"feed must be a positive speed in mm/s, got {feed_mm_s}")
    require(math.isfinite(spindle_rpm) and spindle_rpm > 0,
            f"spindle speed must be positive in rpm, got {spindle_rpm}")
    return feed_mm_s * 60.0 / spindle_rpm


def wall_length_from_growth_exponent(p: float, mu_f: float, mu_w: float,
                                     drill: Drill = Drill()) -> float:
    """Invert the growth exponent for the wall contact length l_w [mm].

    With p = ηMD/S (Eq 3.16) and M = μ_f(l_f + l_h + l_r) + l_w μ_f μ_w sin θ (Eq 3.14):

        l_w = (pS/(ηD) − μ_f(l_f + l_h + l_r)) / (μ_f μ_w sin θ).
    """
    M = p * drill.flute_area_mm2 / (drill.eta * drill.diameter_mm)
    sin_theta = math.sin(math.radians(drill.face_angle_deg))
    return (M - mu_f * drill.flute_length_sum_mm) / (mu_f * mu_w * sin_theta)
