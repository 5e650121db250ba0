"""The candidate mechanisms, one module each, and the simulation they modify.

:mod:`.registry` says what a mechanism is and lists the catalogue; :mod:`.problem` is the
forward model that applies them. Adding a mechanism is adding a module here (docs/diagnosis.md,
"Adding a mechanism").
"""

from femstudy.diagnosis.mechanisms.problem import Geometry, Problem
from femstudy.diagnosis.mechanisms.registry import Mechanism, catalogue, mechanism, names

__all__ = ["Geometry", "Mechanism", "Problem", "catalogue", "mechanism", "names"]
