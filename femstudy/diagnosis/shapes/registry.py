"""The registry of the shapes outside the catalogue: what a shape is (:class:`ShapeKind`), the
context its columns are made in, and :data:`SHAPES`, filled by :func:`register` from each
shape's module (see the package)."""


from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Context:
    """What a shape's candidates and columns are made of."""

    t: np.ndarray                 #: model grid [s]
    cut: tuple[float, float]      #: contact and feed stop on the recording's clock [s]
    step_s: float                 #: scan step (half the band's Gaussian width) [s]
    sigma_s: float                #: the band's Gaussian width [s]
    feed_mm_s: float
    cone_mm: float
    cortex_mm: float
    channels: tuple[str, ...]

    step_dec_s: float = 0.0       #: the analysis instants' spacing [s]

    @property
    def highest_hz(self) -> float:
        """80 % of the Nyquist frequency of the analysis instants."""
        return 0.8 * 0.5 / self.step_dec_s

    @property
    def in_cut(self) -> np.ndarray:
        return (self.t >= self.cut[0]) & (self.t <= self.cut[1])


class ShapeKind(Protocol):
    """A registered shape (see the package docstring)."""

    kind: str
    #: columns per candidate, and scanned parameters (counted in the BIC and the look-elsewhere allowance)
    width: int
    scanned: int
    #: whether it may replace mechanisms (:mod:`..verdict`); ``one_channel_competes``: only on one channel
    competes: bool
    one_channel_competes: bool
    #: the first column is a fixed change of the model (coefficient 1), not an amplitude
    fixed_first: bool
    #: least size that is reported (fraction of the load; for a re-timing, its stretch)
    min_size: float

    def candidates(self, ctx: Context) -> list[dict]: ...

    def columns(self, ctx: Context, channel: int, load: np.ndarray, p: dict) -> list[np.ndarray]: ...

    def interval(self, ctx: Context, p: dict) -> tuple[float, float]: ...

    def refine(self, ctx: Context, p: dict) -> list[dict]: ...

    def size(self, parameters: dict, coefficients: tuple, used: tuple) -> float: ...

    def describe(self, names: list[str], coefficients: dict, parameters: dict, one_channel: bool) -> tuple[str, str]: ...


#: The registered shapes, in module name order.
SHAPES: dict[str, ShapeKind] = {}


def register(shape: ShapeKind) -> ShapeKind:
    if shape.kind in SHAPES:
        raise ValueError(f"shape {shape.kind} registered twice")
    SHAPES[shape.kind] = shape
    return shape


WORD = {"thrust_N": "thrust", "torque_Nmm": "torque"}


def amounts(names: list[str], coefficients: dict) -> str:
    """'the thrust by +x % and the torque by +y %' from each channel's first amplitude."""
    return " and ".join(f"the {WORD[n]} by {100 * float(coefficients[n][0]):+.1f} %" for n in names)


def local_change(names: list[str], coefficients: dict, one_channel: bool, what: str, where: str) -> tuple[str, str]:
    """(kind, description) of a change for a while, as from a harder or softer layer: ``bump`` on
    both channels, ``thrust_only``/``torque_only`` on one; ``what`` says when, ``where`` where
    the amounts apply ('there', 'inside it')."""
    only = f", {WORD[names[0]]} only" if one_channel else ""
    kind = f"{WORD[names[0]]}_only" if one_channel else "bump"
    return kind, f"{what}: {amounts(names, coefficients)} {where}{only}, as from a harder or softer layer of bone."


