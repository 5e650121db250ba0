"""Shape-flexible bases: monotone splines and orthogonal polynomials on an interval.

A mechanism whose law is known only up to its shape is fitted as a non-negative combination of
**I-splines** (Ramsay 1988): integrals of quadratic B-splines, each rising monotonically from 0 to
1 across a few knot intervals. Any non-negative combination is a non-decreasing, continuously
differentiable function that starts at 0; with ``intervals`` equal intervals the cone of such
combinations holds every monotone quadratic spline on those knots, so an exponential, a power
law, a late onset, an S-curve or a saturating rise are all inside it, and a fall is not.

A smooth trend of unknown form is a Legendre series P₁ … P_d on the interval (P₀, the constant,
belongs to the tare).
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.polynomial import legendre
from scipy.interpolate import BSpline

#: Degree of the B-splines whose integrals are the I-splines.
DEGREE = 2


def monotone_basis(x: np.ndarray, lower: float, upper: float, intervals: int) -> np.ndarray:
    """I-splines on [lower, upper] at ``x`` (clipped to the interval): ``x.size`` × (intervals + 2)
    columns, each 0 at ``lower``, 1 at ``upper`` and non-decreasing.

    Examples
    --------
    >>> B = monotone_basis(np.linspace(0, 1, 5), 0.0, 1.0, 3)
    >>> B.shape, bool(np.all(np.diff(B, axis=0) >= 0)), float(B[0].max()), float(B[-1].min())
    ((5, 5), True, 0.0, 1.0)
    """
    span = max(upper - lower, 1e-12)
    u = np.clip((np.asarray(x, float) - lower) / span, 0.0, 1.0)
    return _isplines(intervals)(u)


@functools.lru_cache(maxsize=32)
def _isplines(intervals: int) -> BSpline:
    """The I-splines on [0, 1] as one vector-valued spline (each column's integral normalised to 1)."""
    inner = np.linspace(0.0, 1.0, intervals + 1)
    knots = np.concatenate([[0.0] * DEGREE, inner, [1.0] * DEGREE])
    n = knots.size - DEGREE - 1
    integral = BSpline(knots, np.eye(n), DEGREE).antiderivative()
    return BSpline(integral.t, integral.c / integral(1.0)[None, :], integral.k)


def legendre_basis(x: np.ndarray, lower: float, upper: float, degree: int) -> np.ndarray:
    """P₁ … P_degree of the position in [lower, upper] mapped to [−1, 1]: ``x.size`` × degree."""
    s = 2 * (np.asarray(x, float) - lower) / max(upper - lower, 1e-12) - 1
    return np.column_stack([legendre.legval(s, np.eye(degree + 1)[k]) for k in range(1, degree + 1)])
