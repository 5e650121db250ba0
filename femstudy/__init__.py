"""femstudy: finite-element studies of the femur under surgical-drilling loads.

Units inside the package are mm, N, N·mm, MPa, s and tonne/mm³; other units are accepted
only at the edges (readers, command line) and converted explicitly there.
"""

__version__ = "0.1.0"
