"""The catalogue of candidate mechanisms: what a mechanism is, and where each one is found.

A mechanism is one :class:`Mechanism`, defined and registered (:func:`register`) in its own
module of this package; the catalogue (:func:`catalogue`) imports every module of the package
the first time it is asked for, and lists the mechanisms in alphabetical order of their names
(the order of their parameters and of the fitted subsets). Nothing else names a mechanism: the
forward model (:class:`~.problem.Problem`), the fits (:mod:`..fit`), the selection
(:mod:`..select`) and the explanation (:mod:`..explain`) loop over the catalogue. How to add
one: docs/diagnosis.md, "Adding a mechanism".

How a mechanism acts on the modelled loads (see :mod:`.problem` for the whole model): through
any of its optional hooks,

- ``feed(problem, params, t, t_contact) -> (m, lead)``: the feed runs at f (1 + m(t)) and the
  drill ahead of the nominal depth by f·lead(t) (the simulation is read at τ + lead, the
  cutting loads scaled by 1 + m while cutting);
- ``excess(problem, params, tau, stop) -> C``: an extra thrust C(τ) [N] on the simulated one;
  its torque is k·C with k the linear parameter ``torque_gain`` (≥ 0, per newton of recorded
  extra thrust);
- ``factor(problem, params, t, t_contact) -> H``: a factor on both cutting loads;
- ``linear``: columns on the sensor reading, fitted linearly (:class:`LinearTerm`).
"""

from __future__ import annotations

import importlib
import os
import pkgutil
from dataclasses import dataclass
from typing import Callable

#: Modules of this package that hold no mechanism.
_NOT_MECHANISMS = ("registry", "problem")

_REGISTRY: dict[str, "Mechanism"] = {}


@dataclass(frozen=True)
class Parameter:
    """A nonlinear parameter of a mechanism: its bounds, and when it is fitted.

    ``lower_of``/``upper_of(problem)`` replace a bound that depends on the recording;
    ``optional`` parameters are fitted only in a variant of the fit (:class:`Variant`);
    ``needs(problem)`` false leaves the parameter out; ``held_out_fixed`` keeps it at the full
    fit's value in held-out refits (a parameter pinned by a few instants a fold may hold out)."""

    name: str
    lower: float
    upper: float | None
    lower_of: Callable | None = None
    upper_of: Callable | None = None
    optional: bool = False
    needs: Callable | None = None
    held_out_fixed: bool = False

    def bounds(self, problem) -> tuple[float, float | None]:
        return (self.lower if self.lower_of is None else self.lower_of(problem),
                self.upper if self.upper_of is None else self.upper_of(problem))


@dataclass(frozen=True)
class LinearTerm:
    """A column of every channel's sensor reading, solved for linearly, after the tare (its
    parameter ``name.format(channel=...)``; ``column(problem)`` smoothed, instants)."""

    name: str
    column: Callable


@dataclass(frozen=True)
class Variant:
    """An optional parameter tried where the plain form leaves misfit, from each of ``starts``."""

    parameter: str
    starts: tuple[float, ...]


@dataclass(frozen=True)
class Scan:
    """Candidates of a mechanism for the seeds' linearised scan (:class:`..fit.Linearisation`):
    ``grid(problem)`` the keys scanned, ``columns(problem, base_params, key)`` per channel the
    smoothed columns (columns × instants) of the mechanism linearised at ``key``, shared by the
    channels; ``default`` the key used when the scan finds no minimum."""

    grid: Callable
    columns: Callable
    default: object


@dataclass(frozen=True)
class Mechanism:
    """One candidate missing mechanism: its parameters, how it changes the modelled loads, its
    starting values, its size and threshold, and its explanation.

    Attributes
    ----------
    name : the name reported (``missing_physics[].mechanism``).
    parameters : nonlinear parameters, in the order they are fitted; the first is required.
    seeds : ``seeds(problem, linearisation) -> [dict, ...]``: starting values of the nonlinear
        parameters (:class:`..fit.Linearisation` has the scans); the first is used in every
        subset, the others too when the mechanism is fitted alone.
    size : ``size(problem, params) -> float``: the mechanism's size in a fit, in the units of
        ``threshold``.
    threshold : the least size that counts as missing physics (:mod:`..select`).
    explain : ``explain(problem, params, bone_mu_w) -> (parameters, text)``: the report's
        reading (:mod:`..explain`); ``bone_mu_w`` is the bone set's wall friction.
    feed, excess, factor, linear : how it acts (the module docstring); ``torque_gain`` names the
        linear torque gain on ``excess``.
    variants : optional parameters tried when even all mechanisms leave misfit (:mod:`..fit`).
    stand_in, scan : the mechanism in the seeds' linearised fit (:class:`..fit.Linearisation`):
        ``stand_in(problem, base_params, plain_terms, tau_s)`` per channel an unsmoothed column
        (``tau_s`` the scanned time constant of the stand-ins), or a :class:`Scan` of shared
        columns.
    possible : ``possible(problem) -> bool``: whether the recording can show it at all.
    """

    name: str
    parameters: tuple[Parameter, ...]
    seeds: Callable
    size: Callable
    threshold: float
    explain: Callable
    feed: Callable | None = None
    excess: Callable | None = None
    torque_gain: str | None = None
    factor: Callable | None = None
    linear: tuple[LinearTerm, ...] = ()
    variants: tuple[Variant, ...] = ()
    stand_in: Callable | None = None
    scan: Scan | None = None
    possible: Callable | None = None

    def acts_in(self, params: dict) -> bool:
        """Whether the mechanism acts on the loads for ``params``: they hold its first nonlinear
        parameter (the others may take defaults)."""
        return bool(self.parameters) and self.parameters[0].name in params

    def can_show(self, problem) -> bool:
        return self.possible is None or self.possible(problem)


def register(mechanism: Mechanism) -> Mechanism:
    """Add ``mechanism`` to the catalogue (once per name) and return it."""
    known = _REGISTRY.get(mechanism.name)
    if known is not None and known is not mechanism:
        raise ValueError(f"a mechanism named {mechanism.name!r} is already registered")
    _REGISTRY[mechanism.name] = mechanism
    return mechanism


def unregister(name: str) -> None:
    """Remove a mechanism from the catalogue (tests that register one of their own)."""
    _REGISTRY.pop(name, None)


_loaded = False


def _load() -> None:
    """Import every mechanism module of this package (each registers its mechanism)."""
    for info in pkgutil.iter_modules([os.path.dirname(__file__)]):
        if info.name not in _NOT_MECHANISMS and not info.name.startswith("_"):
            importlib.import_module(f"{__package__}.{info.name}")


def catalogue() -> tuple[Mechanism, ...]:
    """Every registered mechanism, in alphabetical order of their names."""
    global _loaded
    if not _loaded:
        _loaded = True
        _load()
    return tuple(_REGISTRY[n] for n in sorted(_REGISTRY))


def names() -> tuple[str, ...]:
    """The catalogue's mechanism names, in its order."""
    return tuple(m.name for m in catalogue())


def in_order(subset) -> tuple[str, ...]:
    """The names of ``subset`` (any collection of mechanism names) in the catalogue's order: a
    set's own order changes from one process to the next (string hashing), so every loop whose
    order reaches a result or a file goes through this."""
    return tuple(n for n in names() if n in subset)


def mechanism(name: str) -> Mechanism:
    """The registered mechanism ``name``."""
    catalogue()
    return _REGISTRY[name]


def owner(parameter: str) -> Mechanism | None:
    """The mechanism that has the nonlinear ``parameter`` (None for the alignment's)."""
    return next((m for m in catalogue() if any(p.name == parameter for p in m.parameters)), None)


def nonnegative_linear() -> frozenset[str]:
    """The linear parameters constrained to be ≥ 0 (the torque gains)."""
    return frozenset(m.torque_gain for m in catalogue() if m.torque_gain)


def significant(x: float, digits: int = 4) -> float:
    """``x`` to ``digits`` significant figures (the report's parameters)."""
    return float(f"{x:.{digits}g}")
