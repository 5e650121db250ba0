"""Linear elastic finite elements for the femur: assembly, drill loads, clamps, static,
transient and modal analyses, stresses. Units: mm, N, N·mm, MPa, s, tonne/mm³.

Typical use (docs/solver.md)::

    system = assemble(mesh, case.materials, order=2)
    patch = drill_patch(system, site, radius_mm=1.35)
    bc = clamp(system, clamps)
    u = solve_static(system, bc, patch.force(thrust_N, torque_Nmm))
    hist = solve_transient(system, bc, patch.patterns, np.column_stack([F, T]), times_s)
    modes = solve_modal(system, bc, k=6)
    summary = response(system, u, patch, exclusion_radius_mm=4.0)
"""

from femstudy.fe.assembly import FESystem, assemble
from femstudy.fe.constraints import Constraints, clamp, fix_facets
from femstudy.fe.loads import DrillPatch, drill_patch
from femstudy.fe.modal import Modes, solve_modal
from femstudy.fe.post import displacement_magnitude, element_stress, response, von_mises, von_mises_nodal
from femstudy.fe.static import solve_static
from femstudy.fe.transient import TransientResult, solve_transient, step_check

__all__ = ["FESystem", "assemble", "Constraints", "clamp", "fix_facets", "DrillPatch", "drill_patch", "Modes",
           "solve_modal", "displacement_magnitude", "element_stress", "response", "von_mises", "von_mises_nodal",
           "solve_static", "TransientResult", "solve_transient", "step_check"]
