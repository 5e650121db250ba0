"""Linear elastic finite elements for the femur: assembly, drill loads, clamps, one
factorisation shared by static, modal and transient analyses, and response measures.
Units: mm, N, N·mm, MPa, s, tonne/mm³.

Typical use (docs/solver.md)::

    system = assemble(mesh, BoneMaterials(), order=2)
    patch = drill_patch(system, site, radius_mm=1.35)
    fs = factorize(system, clamp(system, clamps))
    u = solve_static(fs, patch.force(thrust_N, torque_Nmm))
    march = solve_transient(fs, patch.patterns, np.column_stack([F, T]), times_s)
    modes = solve_modal(fs, k=6)

``factorize(..., keep=folder)`` serves the solves from solutions an earlier run kept for the
same K_ff and factorises only on a miss (:mod:`femstudy.fe.kept`); ``fs.factor.close()``
stores the new ones.
"""

from femstudy.fe.assembly import FESystem, assemble
from femstudy.fe.constraints import Constraints, clamp, fix_facets
from femstudy.fe.loads import DrillPatch, drill_patch
from femstudy.fe.modal import Modes, solve_modal
from femstudy.fe.outputs import (Channel, History, Measure, StepRecorder, deflection_channel, point_channel,
                                 reduced_history, von_mises_channel)
from femstudy.fe.post import displacement_magnitude, element_stress, von_mises, von_mises_nodal
from femstudy.fe.static import FactorizedSystem, factorize, solve_static
from femstudy.fe.transient import StepCheck, TransientResult, solve_transient, step_check

__all__ = ["FESystem", "assemble", "Constraints", "clamp", "fix_facets", "DrillPatch", "drill_patch", "Modes",
           "solve_modal", "Channel", "History", "Measure", "StepRecorder", "deflection_channel", "point_channel",
           "reduced_history", "von_mises_channel", "displacement_magnitude", "element_stress", "von_mises",
           "von_mises_nodal", "FactorizedSystem", "factorize", "solve_static", "StepCheck", "TransientResult",
           "solve_transient", "step_check"]
