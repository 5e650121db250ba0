"""Numbers taken from the reference thesis (2012, force/torque modelling for bone drilling),
in one place, each with the table or section it comes from.

Units are the solver's: mm, N, MPa, s, tonne/mm³ (the tables' GPa and kg/m³ are converted
here). Values femstudy derives from the thesis, where it leaves them out, are marked as such
and explained in docs/load-models.md.
"""

from __future__ import annotations

#: Table 3-1, the FE model's materials: Young's modulus [MPa], Poisson's ratio, density
#: [tonne/mm³] (16 GPa, 0.4, 1700 kg/m³ cortical; 0.5 GPa, 0.15, 320 kg/m³ cancellous).
TABLE_3_1 = {
    "cortical": {"E_MPa": 16.0e3, "nu": 0.4, "density_t_mm3": 1700e-12},
    "cancellous": {"E_MPa": 0.5e3, "nu": 0.15, "density_t_mm3": 320e-12},
}

#: Table 2-4, human femoral cortical bone strength [MPa]: tension along (longitudinal) and
#: across (tangential) the long axis, compression likewise, and shear; the yield stress is given
#: for longitudinal tension only. Ultimate strains: 0.031 longitudinal, 0.007 tangential tension.
CORTICAL_STRENGTH_MPA = {
    "longitudinal_tension_ultimate": 133.0, "longitudinal_tension_yield": 114.0,
    "transverse_tension_ultimate": 52.0,
    "longitudinal_compression_ultimate": 205.0, "transverse_compression_ultimate": 130.0,
    "shear_ultimate": 67.0,
}
CORTICAL_ULTIMATE_STRAIN = {"longitudinal_tension": 0.031, "transverse_tension": 0.007}
#: Table 2-5, cancellous bone ultimate strength [MPa]: mean and range.
CANCELLOUS_STRENGTH_MPA = {"mean": 7.56, "min": 0.56, "max": 22.9}

#: Chi's density-based thrust needs densities in g/cm³: Table 3-1's, converted.
CORTICAL_DENSITY_G_CM3 = TABLE_3_1["cortical"]["density_t_mm3"] * 1e9
CANCELLOUS_DENSITY_G_CM3 = TABLE_3_1["cancellous"]["density_t_mm3"] * 1e9

#: §4.1.3 and Appendix A: the two-flute surgical twist drill, diameter [mm] and point angle
#: [degrees]; its tip cone is (D/2)/tan(β/2) = 1.35 mm long.
DRILL_DIAMETER_MM = 2.7
DRILL_POINT_ANGLE_DEG = 90.0

#: Derived (the thesis gives no value): the cortical specific cutting energy u1 [MPa] that
#: makes Allotta's full-engagement thrust equal Appendix B's mean initial force
#: (F_o = 25.686 N at f = 1.5 mm/s, N = 1500 rpm), and the cancellous u2 scaled from it by the
#: ratio of the Table 2-5 mean strength to the Table 2-4 longitudinal tensile strength.
CORTICAL_SPECIFIC_ENERGY_MPA = 448.5
CANCELLOUS_SPECIFIC_ENERGY_MPA = round(
    CORTICAL_SPECIFIC_ENERGY_MPA * CANCELLOUS_STRENGTH_MPA["mean"]
    / CORTICAL_STRENGTH_MPA["longitudinal_tension_ultimate"], 1)

#: Table 4-4: low-pass filter stop-band edge [Hz] per feed rate [mm/s].
TABLE_4_4_STOP_HZ = {1.0: 2.2, 1.5: 2.0, 1.75: 1.9, 2.0: 1.8}

#: Table 5-14: maximum deflection [mm], (dynamic: cutting + chip evacuation, static Allotta),
#: per site of §3.3.3.
MAX_DEFLECTION_MM = {
    "mid-diaphysis": (0.04538, 0.009524),
    "proximal": (0.006244, 0.001312),
    "distal": (0.01252, 0.002639),
}
#: Table 5-15: maximum von Mises stress [MPa], (dynamic, static), per site.
MAX_VON_MISES_MPA = {
    "mid-diaphysis": (21.8116, 4.5813),
    "proximal": (0.3071, 0.0642),
    "distal": (0.1856, 0.0391),
}
