"""Which column of a recording is time, thrust, torque ...: by name, unit and an optional map.

A column names its quantity and its unit: ``thrust_N`` (femstudy's own CSV), ``Fz [kN]``,
``Mz (N·m)``, ``Zeit [ms]``, or a bare name with the unit in a separate units row or
property (``Fz`` over ``N``). Recognised names (any case): time ``time``, ``t``, ``zeit``,
``abs time``; thrust ``thrust``, ``fz``; torque ``torque``, ``mz``; ``depth``; ``fx``;
``fy``. A column map (``--columns time=Zeit,thrust=Fz[kN],torque=Mz`` or the metadata key
``columns``) names the column of each quantity, optionally with its unit in brackets;
command-line entries win over the file's. Other columns are ignored.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from femstudy.errors import UserError, require
from femstudy.recordings.units import QUANTITY_UNITS, factor_to_solver, parse_unit

QUANTITIES = tuple(QUANTITY_UNITS)
REQUIRED = ("time", "thrust")
ALIASES = {"time": {"time", "t", "zeit", "abs time"}, "thrust": {"thrust", "fz"}, "torque": {"torque", "mz"},
           "depth": {"depth"}, "fx": {"fx"}, "fy": {"fy"}}
#: femstudy's own column names, suggested when a column has no unit
SOLVER_COLUMNS = {"time": "time_s (seconds)", "thrust": "thrust_N (newtons)",
                  "torque": "torque_Nmm (N·mm) or torque_Nm (N·m)", "depth": "depth_mm (millimetres)",
                  "fx": "fx_N (newtons)", "fy": "fy_N (newtons)"}
#: channel names femstudy writes where a format has no unit in the name (TDMS, DynoWare-like text)
CHANNEL_NAMES = {"time": "Time", "thrust": "Fz", "torque": "Mz", "depth": "Depth", "fx": "Fx", "fy": "Fy"}
_BRACKETED = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*$")


@dataclass(frozen=True)
class Channel:
    """One used column: its index in the file, its quantity, its name as written, its unit
    as written and the factor to femstudy's unit (s, N, N·mm, mm)."""

    index: int
    quantity: str
    label: str
    unit: str
    factor: float


@dataclass(frozen=True)
class ColumnRef:
    """A column-map entry: the column's name and, optionally, its unit."""

    name: str
    unit: str | None = None


def split_name(name: str) -> tuple[str, str | None]:
    """(name, unit) of ``Fz [kN]``, ``Mz (N·m)`` or ``thrust_N``; the unit is None when absent.

    An underscore separates a unit only after a recognised name (``thrust_N``, ``time_ms``)
    or when what follows is a unit (``Kraft_kN``).
    """
    name = name.strip()
    bracketed = _BRACKETED.match(name)
    if bracketed and bracketed.group(1):
        return bracketed.group(1), bracketed.group(2) or None
    parts = name.split("_")
    for k in range(1, len(parts)):
        if quantity_of("_".join(parts[:k])):
            return "_".join(parts[:k]), "_".join(parts[k:]) or None
    if len(parts) > 1 and parse_unit(parts[-1]) is not None:
        return "_".join(parts[:-1]), parts[-1]
    return name, None


_ALL_ALIASES = {alias: quantity for quantity, aliases in ALIASES.items() for alias in aliases}


def quantity_of(base: str) -> str | None:
    """The quantity a column name (without unit) stands for; a one-letter name must match
    exactly ("t" is time, "T" is not)."""
    base = base.strip()
    return _ALL_ALIASES.get(base) if len(base) == 1 else _ALL_ALIASES.get(base.lower())


def parse_column_map(spec: str | Mapping[str, Any] | None, origin: str) -> dict[str, ColumnRef]:
    """``"time=Zeit,thrust=Fz[kN]"`` (or a mapping of the same) as quantity -> ColumnRef.

    Parameters
    ----------
    spec : str, mapping or None
        Comma-separated ``quantity=column`` items; a column may end with ``[unit]``.
    origin : str
        Where the map came from (``"--columns"``, ``"the header key columns"``), for messages.

    Returns
    -------
    dict
        Quantity (``time``, ``thrust``, ``torque``, ``depth``, ``fx``, ``fy``) -> ColumnRef.

    Examples
    --------
    >>> parse_column_map("thrust=Fz[kN], torque=Mz", "--columns")["thrust"]
    ColumnRef(name='Fz', unit='kN')
    """
    if spec is None:
        return {}
    if isinstance(spec, str):
        items = [item for item in (part.strip() for part in spec.split(",")) if item]
        pairs = []
        for item in items:
            quantity, sep, column = item.partition("=")
            require(sep and column.strip(), f"{origin}: '{item}' is not quantity=column (e.g. thrust=Fz)")
            pairs.append((quantity.strip(), column.strip()))
    elif isinstance(spec, Mapping):
        pairs = [(str(k).strip(), v) for k, v in spec.items()]
    else:
        raise UserError(f"{origin} must be text such as \"time=Zeit,thrust=Fz\", got {spec!r}")
    out = {}
    for quantity, column in pairs:
        require(quantity.lower() in QUANTITIES,
                f"{origin}: unknown quantity '{quantity}'; use {', '.join(QUANTITIES)}")
        require(isinstance(column, str) and column.strip(),
                f"{origin}: {quantity} must name a column, got {column!r}")
        bracketed = re.fullmatch(r"(.*?)\s*\[\s*([^\]]*?)\s*\]\s*", column)
        out[quantity.lower()] = ColumnRef(bracketed.group(1), bracketed.group(2) or None) if bracketed else \
            ColumnRef(column.strip())
    return out


def assign_channels(names: Sequence[str], units: Sequence[str | None], column_map: Mapping[str, ColumnRef],
                    source: str, word: str = "column") -> list[Channel]:
    """The channels used, each with its conversion to femstudy's unit.

    Parameters
    ----------
    names : sequence of str
        Column (or channel, variable) names as written in the file.
    units : sequence of str or None
        The unit of each column given apart from its name (a units row, a property), else None.
    column_map : mapping
        Quantity -> ColumnRef from :func:`parse_column_map`; mapped quantities are not guessed.
    source : str
        The file's name, for messages.
    word : str
        What the format calls a column ("column", "channel", "variable").

    Returns
    -------
    list of Channel
        Time and thrust always; torque, depth, fx, fy when present.

    Examples
    --------
    >>> [c.quantity for c in assign_channels(["Zeit [ms]", "Fz", "Mz"], [None, "N", "N*m"], {}, "r.txt")]
    ['time', 'thrust', 'torque']
    """
    found: dict[str, tuple[int, str | None]] = {}
    for quantity, ref in column_map.items():
        found[quantity] = (_find_mapped(names, ref, quantity, source, word), ref.unit)
    taken = {index for index, _ in found.values()}
    for index, name in enumerate(names):
        base, _ = split_name(name)
        quantity = quantity_of(base)
        if quantity is None or quantity in column_map or index in taken:
            continue
        if quantity in found:
            raise UserError(f"recording {source} has two {quantity} {word}s ('{names[found[quantity][0]]}' and "
                            f"'{name}'); name the one to use with --columns {quantity}=NAME")
        found[quantity] = (index, None)
    for quantity in REQUIRED:
        if quantity not in found:
            solver_name, unit_words = SOLVER_COLUMNS[quantity].split(" (")
            listed = ", ".join(n for n in names if n.strip()) or "none"
            raise UserError(f"recording {source} has no {solver_name} {word} ({unit_words}, nor another "
                            f"{quantity} {word} ({', '.join(sorted(ALIASES[quantity]))}) with a unit; "
                            f"its {word}s are: {listed}")
    channels = []
    for quantity, (index, mapped_unit) in found.items():
        label = names[index].strip()
        unit = _unit_of(label, units[index] if index < len(units) else None, mapped_unit, quantity, source, word)
        channels.append(Channel(index, quantity, label, unit, factor_to_solver(unit, quantity, f"recording {source}: {word} '{label}'")))
    return sorted(channels, key=lambda c: c.index)


def _find_mapped(names: Sequence[str], ref: ColumnRef, quantity: str, source: str, word: str) -> int:
    """Index of the column a map entry names: exactly, ignoring case, or by its name without unit."""
    for test in (lambda n: n.strip() == ref.name, lambda n: n.strip().lower() == ref.name.lower(),
                 lambda n: split_name(n)[0].lower() == ref.name.lower()):
        hits = [k for k, n in enumerate(names) if test(n)]
        if hits:
            return hits[0]
    raise UserError(f"recording {source} has no {word} '{ref.name}' for {quantity}; its {word}s are: "
                    f"{', '.join(n for n in names if n.strip()) or 'none'}")


def _unit_of(label: str, separate: str | None, mapped: str | None, quantity: str, source: str, word: str) -> str:
    """The unit from the name, else the units row/property, else the map; a conflict is an error."""
    _, in_name = split_name(label)
    given = in_name or (separate.strip() if separate and separate.strip() else None)
    if mapped and given and mapped != given and parse_unit(mapped) != parse_unit(given):
        raise UserError(f"recording {source}: {word} '{label}' is in {given} but the column map says {mapped}")
    unit = given or mapped
    if unit is None:
        raise UserError(f"recording {source}: {word} '{label}' has no unit; name it {SOLVER_COLUMNS[quantity]}, "
                        f"write the unit in brackets ('{split_name(label)[0]} [unit]') or give it with --columns "
                        f"{quantity}={split_name(label)[0]}[unit]")
    return unit
