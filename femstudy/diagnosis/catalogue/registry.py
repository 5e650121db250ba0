"""The registry of the catalogue: what a mechanism is (:class:`Mechanism`), the records it returns,
and :data:`MECHANISMS`, filled by :func:`register` from each mechanism's module (see the package).

The diagnosis objects a mechanism receives — the problem (:class:`~..problem.Problem`), the model's
frame (:class:`~..model.Frame`), an evaluation (:class:`~..model.Evaluation`) and a fit
(:class:`~..fit.Fit`) — are described, not imported, so this module depends on nothing of the
diagnosis.
"""


from __future__ import annotations

import enum
import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


class Role(enum.Enum):
    LOAD = "load"
    FEED = "feed"
    GAIN = "gain"
    SENSOR = "sensor"


#: A ``GAIN`` mechanism's variant setting (True): the simulation's own chip friction keeps the
#: level it reached once the simulated load falls (after breakthrough), instead of fading with the
#: cut; the model reads it (:func:`femstudy.diagnosis.model._rise`).
FRICTION_STAYS = "friction_stays"


@dataclass(frozen=True)
class Layout:
    """A mechanism's parameters for one variant: names, bounds, starting values; ``counted`` marks
    the parameters that count towards the model's size only when they leave their lower bound
    (the non-negative coefficients of a monotone spline); the others always count."""

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    start: np.ndarray
    counted_when_active: np.ndarray
    scanned: float = 0.0          #: extra BIC cost of the variant's scanned parameters (a searched frequency)

    @property
    def size(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class Term:
    """A mechanism's contribution on the model grid at given parameters, channels × instants, and
    its derivatives (channels × instants × parameters); ``lead``/``lead_jacobian`` only for FEED.

    ``derivatives`` returns the jacobian and the lead's (None but for FEED); they are computed when
    first read: a fit reads them only at the parameters it accepts, not at a trial step it rejects
    (a third of its evaluations)."""

    value: np.ndarray
    derivatives: Callable[[], tuple[np.ndarray, np.ndarray | None]] = field(repr=False, compare=False)
    lead: np.ndarray | None = None

    @functools.cached_property
    def _derived(self) -> tuple[np.ndarray, np.ndarray | None]:
        return self.derivatives()

    @property
    def jacobian(self) -> np.ndarray:
        return self._derived[0]

    @property
    def lead_jacobian(self) -> np.ndarray | None:
        return self._derived[1]


def carried(problem, s: np.ndarray, kappa: float) -> np.ndarray:
    """A thrust shape s (instants) and, when the recording has torque, the torque's κ s: the
    value of a term the torque carries in the ratio κ (channels × instants)."""
    value = np.zeros((len(problem.channels), s.size))
    value[0] = s
    if problem.has_torque:
        value[1] = kappa * s
    return value


def carried_jacobian(problem, columns: np.ndarray, index, s: np.ndarray, theta: np.ndarray, kappa_at: int) -> np.ndarray:
    """Derivatives of :func:`carried` (channels × instants × parameters): ∂s/∂θ[index] =
    ``columns`` in the thrust, κ times them in the torque, and ∂(κ s)/∂κ = s at ``kappa_at``."""
    jac = np.zeros((len(problem.channels), s.size, theta.size))
    jac[0][:, index] = columns
    if problem.has_torque:
        jac[1][:, index] = theta[kappa_at] * columns
        jac[1, :, kappa_at] = s
    return jac


def proportional_term(problem, X: np.ndarray, theta: np.ndarray) -> Term:
    """The term of a thrust shape s = X θ[:k] (X instants × k) that the torque carries in the ratio
    κ = θ[k] (when the recording has torque): value [s, κ s], derivatives ∂/∂θ[:k] = [X, κ X] and
    ∂/∂κ = [0, s]. Clogging and softening are such terms."""
    k = X.shape[1]
    s = X @ theta[:k]
    return Term(carried(problem, s, theta[k] if problem.has_torque else 0.0),
                lambda: (carried_jacobian(problem, X, slice(0, k), s, theta, k), None))


@dataclass(frozen=True)
class Variant:
    """Discrete settings of a mechanism that are not fitted by least squares (a frequency found by a
    scan, a number of harmonics, a polynomial degree), and a label for the report."""

    settings: tuple = ()
    label: str = ""

    def get(self, key: str, default=None):
        return dict(self.settings).get(key, default)


@dataclass(frozen=True)
class Check:
    """One signature test of a named mechanism: passed or not, the figure it rests on and a sentence.
    ``finding``: the ``unexplained`` kind to report when this test fails for a mechanism that is
    otherwise significant (what the data show instead), or empty."""

    name: str
    passed: bool
    value: float
    text: str
    finding: str = ""


@dataclass(frozen=True)
class Parameter:
    """One reported parameter: name (with its unit in the name), value."""

    name: str
    value: float | str


@dataclass(frozen=True)
class Reading:
    """A named mechanism's physical reading: parameters and a paragraph."""

    parameters: tuple[Parameter, ...]
    text: str


class Mechanism(Protocol):
    """What the diagnosis needs from a catalogue mechanism (see the package docstring)."""

    name: str
    role: Role
    #: least size that counts as missing physics, in the units of :meth:`size`
    floor: float
    #: whether :meth:`variants` scans the residual (else they are fixed alternatives)
    scans: bool

    def available(self, problem: object) -> bool: ...

    def variants(self, problem: object, residual: np.ndarray | None, base: object) -> list[Variant]: ...

    def layout(self, problem: object, variant: Variant) -> Layout: ...

    def term(self, problem: object, frame: object, variant: Variant, theta: np.ndarray) -> Term: ...

    def size(self, problem: object, fit: object) -> float: ...

    def checks(self, problem: object, fit: object, refit) -> list[Check]: ...

    def reading(self, problem: object, fit: object, context: dict) -> Reading: ...


#: The registered mechanisms, in registration order (module name order).
MECHANISMS: dict[str, Mechanism] = {}


def register(mechanism: Mechanism) -> Mechanism:
    """Add ``mechanism`` to the catalogue (called by its module)."""
    if mechanism.name in MECHANISMS:
        raise ValueError(f"mechanism {mechanism.name} registered twice")
    MECHANISMS[mechanism.name] = mechanism
    return mechanism


def names() -> tuple[str, ...]:
    return tuple(MECHANISMS)


def in_order(subset) -> tuple[str, ...]:
    """The names of ``subset`` (any collection of mechanism names) in the catalogue's order: a
    set's own order changes from one process to the next (string hashing), so every loop whose
    order reaches a result or a file goes through this."""
    return tuple(n for n in MECHANISMS if n in subset)


