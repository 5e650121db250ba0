"""JSON recordings, as web-based acquisition tools and simulators log them.

One object: ``"columns"`` maps each column name to its list of numbers (``"time_s"``,
``"thrust_N"``, ``"Fz"`` ...), ``"units"`` optionally maps a column name to its unit
(``{"Fz": "kN"}``) and ``"metadata"`` holds the header's keys (``feed_mm_s`` ...)::

    {"metadata": {"feed_mm_s": 1.5, "spindle_rpm": 1500},
     "units": {"t": "ms"},
     "columns": {"t": [0, 1, 2], "thrust_N": [0.1, 0.2, 0.4], "torque_Nmm": [0, 1, 3]}}

The file is told by its first non-blank character, ``{``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.errors import UserError, require
from femstudy.recordings.formats.registry import Reader, Writer, register_reader, register_writer
from femstudy.recordings.formats.table import Table
from femstudy.recordings.metadata import plain_value


def read_table(path: Path, source: str) -> Table:
    """A JSON recording as a :class:`Table` (see the module docstring)."""
    try:
        document = json.loads(path.read_text(encoding="utf-8-sig"))
    except ValueError as exc:
        raise UserError(f"recording {source} is not readable JSON ({exc})") from None
    require(isinstance(document, dict) and isinstance(document.get("columns"), dict) and document["columns"],
            f"recording {source} (JSON) needs an object with \"columns\": {{name: [numbers], ...}}")
    columns, units = document["columns"], document.get("units") or {}
    metadata = document.get("metadata") or {}
    require(isinstance(units, dict) and isinstance(metadata, dict),
            f"recording {source} (JSON): \"units\" and \"metadata\" must be objects")
    names = list(columns)
    return Table(names=names, units=[units.get(n) for n in names],
                 metadata={k: plain_value(v) for k, v in metadata.items()},
                 origins={k: f"metadata key {k}" for k in metadata},
                 load=lambda indices: _load(columns, names, indices, source),
                 where=lambda row: f"sample {row + 1}", how_to_add='add "{key}" to the "metadata" object')


def _load(columns: dict, names: list[str], indices: list[int], source: str) -> list[np.ndarray]:
    out = []
    for k in indices:
        values = columns[names[k]]
        require(isinstance(values, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                 for v in values),
                f"recording {source}: column '{names[k]}' must be a list of numbers")
        out.append(np.asarray(values, dtype=float))
    sizes = {names[k]: a.size for k, a in zip(indices, out)}
    require(len(set(sizes.values())) <= 1, f"recording {source}: its columns differ in length ("
            + ", ".join(f"'{n}' {s} samples" for n, s in sizes.items()) + ")")
    return out


def write_table(path, columns: list[tuple[str, str, np.ndarray]], metadata: dict) -> None:
    """Write (quantity, unit, values) columns as ``quantity_unit`` lists, and the metadata (atomically)."""
    from femstudy.recordings.formats.text import compact_unit

    document = {"metadata": {k: (list(v) if isinstance(v, tuple) else v) for k, v in metadata.items()},
                "columns": {f"{quantity}_{compact_unit(unit)}": [float(x) for x in values]
                            for quantity, unit, values in columns}}
    atomic.write_text(path, json.dumps(document))


register_reader(Reader("json", read_table, lambda head: head.lstrip(b"\xef\xbb\xbf \t\r\n").startswith(b"{"),
                       (".json",), {".json": "a JSON recording"}))
register_writer(Writer("json", write_table, ".json", default_for_suffix=True))
