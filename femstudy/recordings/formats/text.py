"""Delimited text recordings: femstudy's CSV and what acquisition software and Excel export.

Read: UTF-8 with or without a byte-order mark (Excel's "CSV UTF-8"), UTF-16 with one
(Excel's "Unicode text"); LF or CRLF line ends. The delimiter (tab, ``;`` or ``,``) and the
decimal mark (``.`` or, with tab or ``;``, ``,``) are sniffed from the first data rows, a
data row being the first line whose fields are all numbers. Above it, from the bottom:
an optional units row (every field a unit or empty, as Kistler's BioWare/DynoWare exports
write under the channel names), the column names, and a header block. Metadata are
``# key = value`` lines (TOML values) anywhere above the data, and ``key<delimiter>value``
or ``key:<delimiter>value`` lines of the header block whose key is a name (``feed_mm_s``);
other header lines are free text.

Written: :class:`TextStyle` — ``# key = value`` lines and ``quantity_unit`` columns
(``time_s,thrust_N,torque_Nmm``), or a DynoWare-like block: a title, ``key:<tab>value``
lines, a channel-name row and a units row.
"""

from __future__ import annotations

import io
import itertools
import logging
import re
import time
import tomllib
import warnings
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Iterator

import numpy as np

from femstudy import atomic
from femstudy.errors import UserError
from femstudy.recordings.columns import CHANNEL_NAMES
from femstudy.recordings.formats.registry import Reader, Writer, register_reader, register_writer
from femstudy.recordings.formats.table import Table
from femstudy.recordings.metadata import format_header_value, parse_text_value
from femstudy.recordings.units import is_units_row

log = logging.getLogger(__name__)

MAX_HEADER_BYTES = 64 * 1024
#: Data lines parsed at a time; after each block the progress is reported.
CHUNK_ROWS = 1_000_000
#: Longest a recording's values may take to read [s] (25 million rows take about 30 s).
READ_TIME_LIMIT_S = 120.0
DELIMITERS = ("\t", ";", ",")
#: lines looked at after the first data row to tell a decimal comma
DECIMAL_SNIFF_LINES = 200
_KEY_LINE = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*\s*=")
_BLOCK_KEY = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)\s*:?\s*$")


@dataclass(frozen=True)
class Layout:
    """Where things are in a text recording: 1-based line numbers, delimiter, decimal mark."""

    encoding: str
    delimiter: str
    decimal: str
    first_data_line: int


def read_table(path: Path, source: str) -> Table:
    """A delimited text recording as a :class:`Table` (see the module docstring)."""
    encoding = _encoding(path, source)
    try:
        with path.open("r", encoding=encoding) as stream:
            comments, lines, data_line, delimiter, decimal = _scan(stream, source)
    except UnicodeDecodeError:
        raise UserError(f"recording {source} is not a text (UTF-8) CSV file") from None
    if not lines:
        raise UserError(f"recording {source} has no column line (expected e.g. 'time_s,thrust_N,torque_Nmm' "
                        f"after the '#' metadata lines)")
    if data_line is None:  # no row of numbers: the first line names the columns
        names_at, units_at, block = lines[0], None, []
        delimiter = next((d for d in DELIMITERS if d in names_at[1]), ",")
        data_line = names_at[0] + 1
    else:
        names_at, units_at = lines[-1], None
        if len(lines) >= 2 and _is_units_row(lines[-1][1], lines[-2][1], delimiter):
            names_at, units_at = lines[-2], lines[-1]
        block = lines[: lines.index(names_at)]
    names = _fields(names_at[1], delimiter)
    units = _fields(units_at[1], delimiter) if units_at else [None] * len(names)
    metadata, origins = _metadata(comments, block, delimiter, decimal, source)
    layout = Layout(encoding, delimiter, decimal, data_line)
    return Table(names=names, units=[u or None for u in units], metadata=metadata, origins=origins,
                 load=lambda indices: _load(path, layout, indices, source),
                 where=lambda row: f"line {_line_of_row(path, layout, row)}",
                 how_to_add="add '# {key} = ...' to its header")


def _encoding(path: Path, source: str) -> str:
    with path.open("rb") as raw:
        head = raw.read(4096)
    if head.startswith((b"\xff\xfe", b"\xfe\xff")):
        return "utf-16"
    if b"\x00" in head:
        raise UserError(f"recording {source} is not a text (UTF-8) CSV file, nor a TDMS, MATLAB or .xlsx file")
    return "utf-8-sig"


def _scan(stream, source: str):
    """Comment lines, other non-blank lines before the data, the first data line's number,
    the delimiter and the decimal mark."""
    comments, lines, size = [], [], 0
    for number, line in enumerate(stream, start=1):
        size += len(line)
        if size > MAX_HEADER_BYTES:
            raise UserError(f"recording {source}: the header is longer than {MAX_HEADER_BYTES // 1024} kB "
                            f"before the first row of numbers; is this a recording?")
        text = line.rstrip("\r\n")
        if not text.strip():
            continue
        if text.lstrip().startswith("#"):
            comments.append((number, text.lstrip()[1:].strip()))
            continue
        sniffed = _numeric_row(text)
        if sniffed:
            delimiter, decimal = sniffed
            if delimiter != "," and decimal == ".":
                decimal = _decimal_mark(stream, delimiter)
            return comments, lines, number, delimiter, decimal
        lines.append((number, text))
    return comments, lines, None, ",", "."


def _numeric_row(text: str) -> tuple[str, str] | None:
    """(delimiter, decimal mark) if every field of ``text`` is a number, for some delimiter."""
    for delimiter in DELIMITERS:
        fields = text.rstrip(delimiter + " ").split(delimiter)
        if len(fields) < 2:
            continue
        decimal = "," if delimiter != "," and any("," in f for f in fields) else "."
        if all(_is_number(f, decimal) for f in fields):
            return delimiter, decimal
    return None


def _is_number(field: str, decimal: str) -> bool:
    try:
        float(field.replace(",", ".") if decimal == "," else field)
    except ValueError:
        return False
    return True


def _decimal_mark(stream, delimiter: str) -> str:
    """',' when a later data row of a tab- or ';'-separated file has a comma."""
    for _, line in zip(range(DECIMAL_SNIFF_LINES), stream):
        if "," in line and not line.lstrip().startswith("#"):
            return ","
    return "."


def _fields(text: str, delimiter: str) -> list[str]:
    return [f.strip().strip('"').strip() for f in text.split(delimiter)]


def _is_units_row(candidate: str, above: str, delimiter: str) -> bool:
    """A row of units under as many names (Kistler's exports write one)."""
    fields = _fields(candidate, delimiter)
    return len(fields) == len(_fields(above, delimiter)) and is_units_row(fields)


def _metadata(comments, block, delimiter: str, decimal: str, source: str) -> tuple[dict, dict]:
    """``# key = value`` comment lines (TOML) and ``key<delimiter>value`` header-block lines."""
    values, origins = {}, {}
    for number, text in comments:
        if not _KEY_LINE.match(text):
            continue  # a free-text comment
        try:
            parsed = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise UserError(f"recording {source}, line {number}: '# {text}' is not 'key = value' with a "
                            f"TOML value ({exc}); quote text values") from None
        values.update(parsed)
        origins.update({key: f"line {number}" for key in parsed})
    for number, text in block:
        key_text, _, rest = text.partition(delimiter)
        key = _BLOCK_KEY.match(key_text.strip())
        value = rest.split(delimiter)[0].strip() if rest else ""
        if key and value:
            values[key.group(1)] = parse_text_value(value, decimal)
            origins[key.group(1)] = f"line {number}"
    return values, origins


def _data_lines(path: Path, layout: Layout) -> Iterator[str]:
    """The lines from the first data row on, with a decimal comma made a point."""
    with path.open("r", encoding=layout.encoding) as stream:
        for number, line in enumerate(stream, start=1):
            if number >= layout.first_data_line:
                yield line.replace(",", ".") if layout.decimal == "," else line


def _load(path: Path, layout: Layout, indices: list[int], source: str) -> list[np.ndarray]:
    """The used columns, read :data:`CHUNK_ROWS` lines at a time: a long file reports its
    progress (a bar on a terminal), and one whose reading takes longer than
    :data:`READ_TIME_LIMIT_S` (a slow network drive, say) is stopped with one line."""
    total, done, start = max(path.stat().st_size, 1), 0, time.monotonic()
    lines, blocks = _data_lines(path, layout), []
    while block := list(itertools.islice(lines, CHUNK_ROWS)):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "input contained no data": checked later
                data = np.loadtxt(block, delimiter=layout.delimiter, usecols=indices, ndmin=2, comments="#",
                                  dtype=float)
        except ValueError:
            raise UserError(_first_bad_line(path, layout, indices, source)) from None
        if data.size:
            blocks.append(data)
        done += sum(map(len, block))
        seconds = time.monotonic() - start
        if len(block) == CHUNK_ROWS or blocks[:-1]:
            log.info("read %.0f %% of %s", min(100.0, 100.0 * done / total), source,
                     extra={"progress": (f"reading {source}", min(done, total), total)})
        if seconds > READ_TIME_LIMIT_S:
            raise UserError(f"reading recording {source} took longer than {READ_TIME_LIMIT_S:g} s "
                            f"({100.0 * done / total:.0f} % read); copy it to a local disk, or split it")
    if len(blocks) > 1 or done >= CHUNK_ROWS:
        log.info("read %s", source, extra={"progress": (f"reading {source}", None, None)})
    if not blocks:
        return [np.empty(0) for _ in indices]
    data = np.concatenate(blocks) if len(blocks) > 1 else blocks[0]
    return [data[:, k] for k in range(len(indices))]


def _rows(path: Path, layout: Layout) -> Iterator[tuple[int, str]]:
    """(line number, text) of every data row (blank and comment lines skipped)."""
    for number, line in enumerate(_data_lines(path, layout), start=layout.first_data_line):
        text = line.strip()
        if text and not text.startswith("#"):
            yield number, text


def _first_bad_line(path: Path, layout: Layout, indices: list[int], source: str) -> str:
    """Locate the first data line that is not a row of numbers (slow path, errors only)."""
    for number, text in _rows(path, layout):
        fields = [f.strip() for f in text.split(layout.delimiter)]
        if len(fields) <= max(indices):
            return f"recording {source}, line {number}: {len(fields)} values, expected one per column"
        for k in indices:
            try:
                float(fields[k])
            except ValueError:
                shown = fields[k].replace(".", ",") if layout.decimal == "," else fields[k]
                return f"recording {source}, line {number}: {shown or 'an empty field'} in column {k + 1} " \
                       f"is not a number"
    return f"recording {source}: the data rows do not all have the same number of values"


def _line_of_row(path: Path, layout: Layout, row: int) -> int:
    """1-based line number of data row ``row``."""
    for seen, (number, _) in enumerate(_rows(path, layout)):
        if seen == row:
            return number
    return layout.first_data_line + row


# -- writing ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class TextStyle:
    """How a text recording is written: delimiter, decimal mark, byte-order mark, line end,
    and ``block_header`` for the DynoWare-like layout (a ``key:<tab>value`` block, channel
    names Fz/Mz and a units row) instead of ``# key = value`` lines and unit-named columns."""

    delimiter: str = ","
    decimal: str = "."
    bom: bool = False
    newline: str = "\n"
    block_header: bool = False


def write_table(path, columns: list[tuple[str, str, np.ndarray]], metadata: dict, style: TextStyle) -> None:
    """Write (quantity, unit, values) columns and metadata as text in ``style`` (atomically)."""
    d = style.delimiter
    lines = []
    if style.block_header:
        time = columns[0][2]
        lines += ["femstudy recording export", f"Rate (Hz):{d}{1.0 / float(np.median(np.diff(time))):.6f}"
                  if time.size > 1 else f"Rate (Hz):{d}", f"Samples (#):{d}{time.size}"]
        lines += [f"{key}:{d}{format_header_value(value)}" for key, value in metadata.items()]
        lines.append(d.join(f"abs time ({unit})" if quantity == "time" else CHANNEL_NAMES[quantity]
                            for quantity, unit, _ in columns))
        lines.append(d.join("" if quantity == "time" else unit for quantity, unit, _ in columns))
    else:
        lines += [f"# {key} = {format_header_value(value)}" for key, value in metadata.items()]
        lines.append(d.join(f"{quantity}_{compact_unit(unit)}" for quantity, unit, _ in columns))
    body = io.StringIO()
    np.savetxt(body, np.column_stack([c[2] for c in columns]), delimiter=d,
               fmt=["%.9g" if quantity == "time" else "%.6g" for quantity, _, _ in columns])
    data = body.getvalue().replace(".", ",") if style.decimal == "," else body.getvalue()
    text = "\n".join(lines) + "\n" + data
    with atomic.atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8-sig" if style.bom else "utf-8", newline=style.newline) as out:
            out.write(text)


def compact_unit(unit: str) -> str:
    """A unit as a column-name suffix: ``N·m`` → ``Nm``, ``lbf*in`` → ``lbfin``."""
    return re.sub(r"[\s·*⋅]", "", unit)


register_reader(Reader("text", read_table, None, (".csv", ".tsv", ".txt")))
for _name, _style, _suffix in (("csv", TextStyle(), ".csv"), ("csv-semicolon", TextStyle(delimiter=";"), ".csv"),
                               ("tsv", TextStyle(delimiter="\t"), ".tsv"),
                               ("decimal-comma", TextStyle(delimiter=";", decimal=","), ".csv"),
                               ("excel-csv", TextStyle(delimiter=";", decimal=",", bom=True, newline="\r\n"), ".csv"),
                               ("dynoware", TextStyle(delimiter="\t", block_header=True), ".txt")):
    register_writer(Writer(_name, partial(write_table, style=_style), _suffix,
                           default_for_suffix=_name in ("csv", "tsv", "dynoware")))
