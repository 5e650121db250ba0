"""Published numbers the study is compared with (reference thesis, §2.2 and §5.9)."""

from __future__ import annotations

from femstudy.femur_model import CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL

#: Table 5-14: maximum deflection [mm], dynamic (cutting + chip evacuation) and static Allotta.
MAX_DEFLECTION_MM = {
    "mid-diaphysis": (0.04538, 0.009524),
    "proximal": (0.006244, 0.001312),
    "distal": (0.01252, 0.002639),
}
#: Table 5-15: maximum von Mises stress [MPa], dynamic and static.
MAX_VON_MISES_MPA = {
    "mid-diaphysis": (21.8116, 4.5813),
    "proximal": (0.3071, 0.0642),
    "distal": (0.1856, 0.0391),
}

#: Strength limits per region [MPa] for the margin to failure, with their source.
#: Cortical: Table 2-4, longitudinal tension (yield 114, ultimate 133 MPa) — the lowest
#: longitudinal limits; shear ultimate is 67 MPa and tangential tension 52 MPa, so a
#: von Mises margin against 114 MPa is optimistic for transverse or shear-dominated states.
#: Cancellous: Table 2-5, mean ultimate strength 7.56 MPa (range 0.56–22.9 MPa).
STRENGTH_MPA = {
    CORTICAL: {"yield": 114.0, "ultimate": 133.0, "source": "thesis Table 2-4, longitudinal tension"},
    CANCELLOUS_PROXIMAL: {"ultimate": 7.56, "source": "thesis Table 2-5, mean (range 0.56-22.9)"},
    CANCELLOUS_DISTAL: {"ultimate": 7.56, "source": "thesis Table 2-5, mean (range 0.56-22.9)"},
}
