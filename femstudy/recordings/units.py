"""Units of recording columns, converted to femstudy's s, N, N·mm and mm through pint.

A column's unit is whatever pint reads (``ms``, ``kN``, ``lbf``, ``N*m``, ``N·m``, ``lbf in``,
``ozf*in`` ...), after spelling out the concatenations acquisition software writes
(``Nmm`` → ``N*mm``, ``Nm`` → ``N*m``; pint alone reads ``Nm`` as a "number-metre").
A unit of the wrong dimension, or one pint does not know, is one UserError sentence.
"""

from __future__ import annotations

import functools
import re

from femstudy.errors import UserError

#: quantity -> (femstudy's unit, the dimension's name, examples for messages)
QUANTITY_UNITS = {
    "time": ("s", "time", "s, ms or min"),
    "thrust": ("N", "force", "N, kN or lbf"),
    "torque": ("N*mm", "torque", "N·mm, N·m or lbf·in"),
    "depth": ("mm", "length", "mm or m"),
    "fx": ("N", "force", "N, kN or lbf"),
    "fy": ("N", "force", "N, kN or lbf"),
}
#: (femstudy's unit, a unit as :func:`normalise_unit` writes it) -> the factor between them, for
#: the SI multiples recordings are most often written in: pint's answers (a test holds them
#: equal), kept so that reading such a recording does not import pint and build its registry
#: (0.8 s). Keyed by femstudy's unit, so every quantity of a dimension (thrust, fx, fy) shares them.
SI_FACTORS = {
    ("s", "ms"): 1e-3, ("s", "us"): 1e-6, ("s", "min"): 60.0,
    ("N", "kN"): 1e3, ("N", "mN"): 1e-3, ("N", "daN"): 10.0,
    ("N*mm", "N*m"): 1e3, ("N*mm", "N*cm"): 10.0, ("N*mm", "kN*m"): 1e6, ("N*mm", "mN*m"): 1.0,
    ("mm", "m"): 1e3, ("mm", "cm"): 10.0, ("mm", "um"): 1e-3,
}
_CONCATENATED = re.compile(r"(k?N|daN|mN|lbf|ozf|kgf)(mm|cm|dm|m|in|ft)")
_PRODUCT_SIGNS = re.compile(r"\s*[·⋅•×∙]\s*|(?<=[A-Za-z])-(?=[A-Za-z])")


@functools.lru_cache(maxsize=1)
def registry():
    """The pint unit registry, built from pint's definitions once per process.

    pint's disk cache stays off (``cache_folder=None``, pint's default): it is a folder
    femstudy does not own, shared with every program using pint, whose entries pint
    unpickles, so a half-written entry made valid units unknown and a planted one would run
    code. Building the registry without it costs about a second, once, and only when a
    recording has units other than femstudy's own and the SI multiples of :data:`SI_FACTORS`."""
    import pint

    return pint.UnitRegistry(cache_folder=None)


def normalise_unit(text: str) -> str:
    """A unit as pint reads it: ``N·m``, ``N-m``, ``Nm`` → ``N*m``; ``Nmm`` → ``N*mm``."""
    text = _PRODUCT_SIGNS.sub("*", text.strip())
    match = _CONCATENATED.fullmatch(text)
    return f"{match.group(1)}*{match.group(2)}" if match else text


def parse_unit(text: str):
    """The pint unit of ``text``, or None when pint does not read it as a unit."""
    try:
        unit = registry().parse_units(normalise_unit(text))
    except Exception:  # pint's parser raises PintError, TokenError, AssertionError, ZeroDivisionError ...
        return None
    return None if unit.dimensionless else unit


def dimension_name(unit) -> str:
    """'a time', 'a force', 'a torque', 'a length' ... or pint's dimensionality for any other unit."""
    ureg = registry()
    for word, reference in (("time", ureg.s), ("force", ureg.N), ("torque", ureg.N * ureg.m),
                            ("length", ureg.m), ("mass", ureg.kg), ("pressure", ureg.Pa)):
        if unit.dimensionality == reference.dimensionality:
            return f"a {word}"
    return f"dimension {unit.dimensionality}"


def factor_to_solver(unit_text: str, quantity: str, subject: str) -> float:
    """Multiply a ``quantity`` in ``unit_text`` by this to get it in femstudy's unit.

    Parameters
    ----------
    unit_text : str
        The unit as written (``"kN"``, ``"N·m"``, ``"ms"``).
    quantity : str
        One of :data:`QUANTITY_UNITS` (``"time"``, ``"thrust"``, ``"torque"`` ...).
    subject : str
        What has the unit, to begin the message when it does not fit
        (``"recording rec.csv: column 'Fz'"``).

    Returns
    -------
    float
        The conversion factor (1000 for kN → N, 1e-3 for ms → s, 1000 for N·m → N·mm).

    Examples
    --------
    >>> factor_to_solver("kN", "thrust", "column 'Fz [kN]'")
    1000.0
    """
    target, dimension, examples = QUANTITY_UNITS[quantity]
    written = normalise_unit(unit_text)
    if written == target:
        return 1.0  # femstudy's own unit: nothing to convert, and no need to load pint's registry
    if (target, written) in SI_FACTORS:
        return SI_FACTORS[target, written]
    unit = parse_unit(unit_text)
    if unit is None:
        raise UserError(f"{subject} has unit '{unit_text}', which is not a unit femstudy knows; {quantity} needs "
                        f"a {dimension} unit such as {examples}")
    ureg = registry()
    if unit.dimensionality != ureg.parse_units(target).dimensionality:
        raise UserError(f"{subject} is in {unit_text} ({dimension_name(unit)}); {quantity} needs a {dimension} "
                        f"unit such as {examples}")
    return float(ureg.Quantity(1.0, unit).to(target).magnitude)


def is_units_row(cells: list[str]) -> bool:
    """True when every non-empty cell is a unit and one at least is a time, force, torque or
    length: a row of units under the column names, not a row of names."""
    units = [parse_unit(c) for c in cells if c]
    return bool(units) and all(u is not None for u in units) and \
        any(dimension_name(u) in ("a time", "a force", "a torque", "a length") for u in units)
