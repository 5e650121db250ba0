"""The registry of drilling load models: each model registers itself where it is defined.

A load model gives the thrust [N] and torque [N·mm] of a unicortical hole against time, split
into a *cutting* part (the drill's lips removing bone) and a *chip-evacuation* part (the chips
rubbing in the flutes and on the hole wall): the study applies the first on the drill-point
cone and the second as wall friction (docs/hole.md). A new model is one module in
:mod:`femstudy.drilling.models` that calls :func:`register`; every module there is imported
when the registry is first read, so nothing else needs to change.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from femstudy.errors import require

#: What a model can be used for: a study's dynamic loading (thrust and torque of the whole
#: hole), a synthetic recording, the simulation a recording is diagnosed against.
USES = ("study", "synthesis", "diagnosis")


@dataclass(frozen=True)
class LoadParts:
    """Thrust [N] and torque [N·mm] of a model at some times, as cutting and chip-evacuation parts
    (zeros where a model has no evacuation; NaN torque where it has no torque)."""

    cutting_thrust_N: np.ndarray
    cutting_torque_Nmm: np.ndarray
    evacuation_thrust_N: np.ndarray
    evacuation_torque_Nmm: np.ndarray

    @property
    def thrust_N(self) -> np.ndarray:
        return self.cutting_thrust_N + self.evacuation_thrust_N

    @property
    def torque_Nmm(self) -> np.ndarray:
        return self.cutting_torque_Nmm + self.evacuation_torque_Nmm


@dataclass(frozen=True)
class LoadModel:
    """One drilling load model.

    name : what case files and the command line call it
    title : its legend, with the thesis's equations
    colour : the colour of its curves (matplotlib)
    parts : ``parts(cond, t_s, depth_mm, content) -> LoadParts``, vectorised in time, ``cond`` the
        operating point (``DrillingConditions``); ``content`` (``DynamicContent``) may change how the
        evacuation part is released at breakthrough; the per-flute oscillation is applied to the
        total by the caller (:func:`femstudy.drilling.history.evaluate`)
    uses : a subset of :data:`USES`
    rank : its place in tables and figures of every model
    """

    name: str
    title: str
    colour: str
    parts: Callable[..., LoadParts]
    uses: tuple[str, ...] = USES
    rank: int = 100


_MODELS: dict[str, LoadModel] = {}


def register(model: LoadModel) -> LoadModel:
    """Add ``model`` to the registry (a name may be registered once)."""
    require(model.name not in _MODELS, f"a load model named '{model.name}' is already registered")
    require(set(model.uses) <= set(USES), f"load model '{model.name}': uses must be among {', '.join(USES)}")
    _MODELS[model.name] = model
    return model


def _discover() -> None:
    import femstudy.drilling.models  # noqa: F401  (its import registers every model module)


def names(use: str | None = None) -> tuple[str, ...]:
    """The registered models' names in table order, those fit for ``use`` only when given."""
    _discover()
    found = sorted(_MODELS.values(), key=lambda m: (m.rank, m.name))
    return tuple(m.name for m in found if use is None or use in m.uses)


def get(name: str, use: str | None = None) -> LoadModel:
    """The model called ``name`` (fit for ``use`` when given), or a UserError naming the choices."""
    choices = names(use)
    purpose = f" for a {use}" if use else ""
    require(name in choices, f"unknown load model '{name}'{purpose}: choose one of {', '.join(choices)}")
    return _MODELS[name]
