"""Length units a femur surface may come in, and the femur lengths each makes plausible.

A surface file carries no unit; :func:`femstudy.meshing.frame.detect_units` picks the one
that makes the bone femur-sized, and :func:`femstudy.meshing.surface.read_surface` refuses a
file that no unit makes femur-sized before VTK sees it.
"""

#: Factor from each unit to mm.
UNIT_SCALE = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
#: Plausible femur lengths in each unit (an adult femur is 250-700 mm).
UNIT_RANGES = {"m": (0.2, 0.75), "in": (8.0, 24.0), "cm": (24.5, 75.0), "mm": (200.0, 750.0)}
