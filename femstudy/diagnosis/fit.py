"""Fitting one model: bounded Gauss–Newton on the whitened residual, and the fitted result.

The model (:mod:`.model`) is linear in every mechanism's coefficients and bilinear where a
mechanism multiplies another (a feed pulsation modulates the clogging load, softening both), so
Gauss–Newton from zero converges in a few steps. Each step solves the linearised problem
exactly under the bounds (bounded-variable least squares, :func:`.bounded.bvls`), so a monotone
spline's non-negative coefficients that are not needed sit exactly at zero and do not count
towards the model's size; a step that raises χ² is halved. Residuals are
whitened by the noise model (generalised least squares), so the cost is χ².

The size of a fit, for the information criterion: every parameter that is always free (tares,
alignment, drift coefficients, couplings), the bounded coefficients that left their bound, and
the cost of the mechanisms' scanned settings (a frequency searched over a range:
:attr:`~.catalogue.Layout.scanned`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from femstudy.diagnosis.bounded import bvls_from, triangular
from femstudy.diagnosis.model import Evaluation, ParameterLayout, Spec, evaluate, layout
from femstudy.diagnosis.problem import Problem

#: Gauss–Newton iterations at most, and the relative χ² change that ends them.
MAX_ITERATIONS = 12
TOLERANCE = 1e-5
#: ... or this absolute change of χ² (far below any decision, which needs ten), and the halvings of
#: a step that raises χ² before the fit stops where it is.
ABSOLUTE_TOLERANCE = 0.05
HALVINGS = 2
#: Levenberg damping, relative to the mean diagonal of JᵀJ (keeps couplings with a zero column defined).
DAMPING = 1e-7


@dataclass(frozen=True)
class Fit:
    """One model's optimum: the spec, its parameters, χ² per channel over the fitted rows, the
    smoothed model at every instant, and its size; ``evaluation`` (the model with its
    derivatives at the optimum) is built by ``evaluated`` when first read."""

    spec: Spec
    layout: ParameterLayout
    theta: np.ndarray
    chi2: np.ndarray
    model: np.ndarray
    n_params: float
    evaluated: Callable[[], Evaluation] = field(repr=False, compare=False)

    @functools.cached_property
    def evaluation(self) -> Evaluation:
        return self.evaluated()

    @property
    def subset(self) -> frozenset:
        return self.spec.subset

    @property
    def chi2_total(self) -> float:
        return float(self.chi2.sum())

    def value(self, name: str, default: float | None = None) -> float:
        if name not in self.layout.names:
            if default is None:
                raise KeyError(name)
            return default
        return float(self.theta[self.layout.index(name)])

    def block(self, mechanism: str) -> np.ndarray:
        return self.theta[self.layout.blocks[mechanism]]

    def params(self) -> dict:
        """Every parameter by name (a start for another fit)."""
        return dict(zip(self.layout.names, map(float, self.theta)))


def _whitened_residual(problem: Problem, ev: Evaluation, rows: np.ndarray) -> list[np.ndarray]:
    """Whitened residual per channel."""
    return [problem.whiten(c, problem.y[c] - ev.model[c], rows) for c in range(len(problem.channels))]


def _whitened_jacobian(problem: Problem, ev: Evaluation, rows: np.ndarray) -> np.ndarray:
    """Whitened derivatives, channels stacked."""
    return np.vstack([problem.whiten(c, ev.jacobian[c], rows) for c in range(len(problem.channels))])


def fit(problem: Problem, spec: Spec, start: dict | None = None, rows: np.ndarray | None = None,
        fixed: tuple[str, ...] = ()) -> Fit:
    """The optimum of ``spec`` on ``rows`` (default: the usable instants), from the layout's start
    overridden by ``start`` (by name), with the parameters named in ``fixed`` held."""
    rows = problem.usable if rows is None else rows & problem.usable
    lay = layout(problem, spec)
    theta = lay.start.copy()
    for k, name in enumerate(lay.names):
        if start and name in start:
            theta[k] = start[name]
    theta = np.clip(theta, lay.lower, lay.upper)
    free = np.array([name not in fixed for name in lay.names])
    ev = evaluate(problem, spec, lay, theta)
    parts = _whitened_residual(problem, ev, rows)
    r = np.concatenate(parts)
    J = _whitened_jacobian(problem, ev, rows)
    chi2 = float(r @ r)
    sides = None   # the bounds that held at the last step's solution: the next one's start
    for _ in range(MAX_ITERATIONS):
        A = J[:, free]
        b = r + A @ theta[free]
        damping = DAMPING * max(float(np.mean(np.einsum("ij,ij->j", A, A))), 1e-300)
        A_aug = np.vstack([A, np.sqrt(damping) * np.eye(A.shape[1])])
        b_aug = np.concatenate([b, np.sqrt(damping) * theta[free]])
        R, c = triangular(A_aug, b_aug)   # the same least squares on p rows instead of n
        proposal = theta.copy()
        proposal[free], sides = bvls_from(R, c, lay.lower[free], lay.upper[free], sides)
        step, accepted = 1.0, False
        for _ in range(HALVINGS + 1):
            trial = theta + step * (proposal - theta)
            ev_trial = evaluate(problem, spec, lay, trial)
            parts_trial = _whitened_residual(problem, ev_trial, rows)
            r_trial = np.concatenate(parts_trial)
            chi2_trial = float(r_trial @ r_trial)
            if chi2_trial <= chi2:
                accepted = True
                break
            step /= 2
        if not accepted:
            break
        improvement = chi2 - chi2_trial
        theta, ev, parts, r, chi2 = trial, ev_trial, parts_trial, r_trial, chi2_trial
        if improvement <= max(ABSOLUTE_TOLERANCE, TOLERANCE * chi2):
            break
        J = _whitened_jacobian(problem, ev, rows)   # only at accepted parameters that step on
    chi2_channels = np.array([float(np.sum(part ** 2)) for part in parts])
    active = lay.counted_when_active & (theta > np.where(lay.counted_when_active, lay.lower, 0.0) + 1e-12)
    counted = np.count_nonzero(~lay.counted_when_active & free) + np.count_nonzero(active & free)
    return Fit(spec, lay, theta, chi2_channels, ev.model, float(counted + np.count_nonzero(~free)) + lay.scanned,
               lambda: ev)
