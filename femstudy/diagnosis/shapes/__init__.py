"""Shapes of what no catalogue mechanism makes: one module each, registered where defined.

A shape is a family of a few columns on the modelled load L_c(t) of a channel (the fitted
simulation with its mechanisms, on the model grid), scanned over its candidates (a step's
instant, a bump's position and width, an oscillation's frequency, a re-timing's stretch and
delay) and fitted by GLS to a residual (:mod:`..outside`). Each module defines one
:class:`ShapeKind` and calls :func:`register`; the modules are imported when the package is, so
adding a shape is one new module.
"""

from femstudy.diagnosis.shapes.registry import SHAPES, WORD, Context, ShapeKind, amounts, register
from femstudy.plugins import import_modules

__all__ = ["SHAPES", "WORD", "Context", "ShapeKind", "amounts", "register"]

import_modules(__name__, __path__, skip=("registry",))
