"""Excel .xlsx recordings, read and written with openpyxl.

The data sheet is the one named ``recording`` or ``data``, else the first. In it, as in a
text export: an optional header block of ``key | value`` rows, a row of column names
(``time [s]``, ``Fz [kN]``, ``thrust_N``), an optional row of units, then rows of numbers.
Metadata are the header block's rows and the ``key | value`` rows of a sheet named
``metadata``, which win. Lists are written as TOML text.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.errors import UserError
from femstudy.recordings.formats.registry import Reader, Writer, register_reader, register_writer
from femstudy.recordings.formats.table import Table
from femstudy.recordings.metadata import format_header_value, plain_value
from femstudy.recordings.units import is_units_row

log = logging.getLogger(__name__)

ZIP_SIGNATURE = b"PK\x03\x04"
DATA_SHEETS = ("recording", "data")
METADATA_SHEET = "metadata"
#: Rows and columns read from a sheet at most: a recording's samples (femstudy's limit,
#: femstudy.recordings.reader.MAX_SAMPLES) plus a header, and far more columns than channels.
MAX_ROWS = 25_000_000 + 1000
MAX_COLUMNS = 256
#: Rows between progress reports, and the longest a sheet may take to read [s].
PROGRESS_ROWS = 100_000
READ_TIME_LIMIT_S = 120.0
#: Largest uncompressed content of a workbook [bytes] (1 GiB, the limit on a recording file).
MAX_UNCOMPRESSED_BYTES = 1 << 30


def _check_archive(path: Path, source: str) -> None:
    """Refuse a workbook whose parts would unpack to more than :data:`MAX_UNCOMPRESSED_BYTES`
    (a zip bomb), before openpyxl unpacks anything."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as book:
            size = sum(info.file_size for info in book.infolist())
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise UserError(f"recording {source} is not a readable Excel .xlsx workbook ({type(exc).__name__}: "
                        f"{exc})") from None
    if size > MAX_UNCOMPRESSED_BYTES:
        raise UserError(f"recording {source} unpacks to {size / 2 ** 30:.1f} GiB; femstudy reads workbooks of up to "
                        f"{MAX_UNCOMPRESSED_BYTES / 2 ** 30:.0f} GiB unpacked: export the recording as CSV and split it")


def _sheet_rows(ws, source: str) -> list[list]:
    """The rows of a read-only sheet as they are in the file. The sheet's ``dimension`` claim
    is dropped first: openpyxl pads every row to the claimed width and height, and a 1.5 kB
    file claiming a million rows by 16,384 columns would fill memory."""
    ws.reset_dimensions()
    rows, start = [], time.monotonic()
    for row in ws.iter_rows(values_only=True):
        if len(rows) >= MAX_ROWS:
            raise UserError(f"recording {source}: sheet '{ws.title}' has more than {MAX_ROWS:,} rows; femstudy reads "
                            "recordings of up to 25 million samples: split it")
        rows.append(list(row[:MAX_COLUMNS]))
        if len(rows) % PROGRESS_ROWS == 0:
            log.info("read %d rows of %s", len(rows), source,
                     extra={"progress": (f"reading {source}", len(rows), None)})
            if time.monotonic() - start > READ_TIME_LIMIT_S:
                raise UserError(f"reading recording {source} took longer than {READ_TIME_LIMIT_S:g} s "
                                f"({len(rows):,} rows read); export it as CSV, which reads in seconds")
    if len(rows) >= PROGRESS_ROWS:
        log.info("read %s", source, extra={"progress": (f"reading {source}", None, None)})
    return rows


def read_table(path: Path, source: str) -> Table:
    """An .xlsx recording as a :class:`Table` (see the module docstring)."""
    import openpyxl

    _check_archive(path, source)
    try:
        with path.open("rb") as stream:  # a stream, so that openpyxl does not insist on the suffix
            book = openpyxl.load_workbook(stream, read_only=True, data_only=True)
            sheets = {ws.title: _sheet_rows(ws, source) for ws in book.worksheets}
            book.close()
    except (OSError, UserError):
        raise
    except Exception as exc:  # openpyxl raises BadZipFile, KeyError, InvalidFileException ... on a damaged file
        raise UserError(f"recording {source} is not a readable Excel .xlsx workbook ({type(exc).__name__}: "
                        f"{exc})") from None
    titles = {t.lower(): t for t in sheets}
    data_title = next((titles[t] for t in DATA_SHEETS if t in titles), next(iter(sheets), None))
    rows = sheets.get(data_title) or []
    first = next((k for k, row in enumerate(rows) if _is_number_row(row)), None)
    if first is None:
        raise UserError(f"recording {source}: sheet '{data_title}' has no row of numbers (expected column "
                        f"names such as 'time [s]', 'thrust [N]' over rows of numbers)")
    above = [(k, row) for k, row in enumerate(rows[:first]) if any(c not in (None, "") for c in row)]
    if not above:
        raise UserError(f"recording {source}: sheet '{data_title}' has no row of column names above its numbers")
    names_at, units_row = above[-1], None
    if len(above) >= 2 and _is_units_row(above[-1][1]):
        names_at, units_row = above[-2], above[-1][1]
    names = [_text(c) for c in names_at[1]]
    units = [(_text(units_row[k]) or None) if units_row and k < len(units_row) else None for k in range(len(names))]
    metadata, origins = {}, {}
    for k, row in above[: above.index(names_at)]:
        _key_value(row, metadata, origins, f"sheet '{data_title}' row {k + 1}")
    for k, row in enumerate(sheets.get(titles.get(METADATA_SHEET, ""), [])):
        _key_value(row, metadata, origins, f"sheet '{titles[METADATA_SHEET]}' row {k + 1}")
    numbered = [(first + 1 + r, row) for r, row in enumerate(rows[first:]) if any(c not in (None, "") for c in row)]
    return Table(names=names, units=units, metadata=metadata, origins=origins,
                 load=lambda indices: _columns(numbered, indices, names, source),
                 where=lambda row: f"row {numbered[row][0]}",
                 how_to_add="add a row '{key} | value' to its metadata sheet")


def _text(cell) -> str:
    return "" if cell is None else str(cell).strip()


def _is_number(cell) -> bool:
    return isinstance(cell, (int, float)) and not isinstance(cell, bool)


def _is_number_row(row) -> bool:
    cells = [c for c in row if c not in (None, "")]
    return len(cells) >= 2 and all(_is_number(c) for c in cells)


def _is_units_row(row) -> bool:
    return is_units_row([_text(c) for c in row])


def _key_value(row, metadata: dict, origins: dict, where: str) -> None:
    """A ``key | value`` row into ``metadata`` (an empty value is the empty text)."""
    cells = list(row) + [None, None]
    key = _text(cells[0])
    if key and key.replace("_", "a").isalnum() and not key[0].isdigit():
        value = cells[1]
        metadata[key] = "" if value is None else plain_value(value)
        origins[key] = where


def _columns(numbered, indices: list[int], names, source: str) -> list[np.ndarray]:
    """The used columns of the (sheet row number, row) pairs as floats; an empty or
    non-number cell is an error naming its row."""
    out = []
    for k in indices:
        values = np.empty(len(numbered))
        for r, (number, row) in enumerate(numbered):
            cell = row[k] if k < len(row) else None
            if not _is_number(cell):
                shown = "an empty cell" if cell in (None, "") else repr(cell)
                raise UserError(f"recording {source}, row {number}: {shown} in column '{names[k]}' is not a number")
            values[r] = cell
        out.append(values)
    return out


def write_table(path, columns: list[tuple[str, str, np.ndarray]], metadata: dict) -> None:
    """Write a sheet ``recording`` (names ``time [s]``, ``thrust [N]`` ... over the numbers)
    and a sheet ``metadata`` of ``key | value`` rows (atomically)."""
    import openpyxl

    book = openpyxl.Workbook(write_only=True)
    sheet = book.create_sheet("recording")
    sheet.append([f"{quantity} [{unit}]" for quantity, unit, _ in columns])
    for row in np.column_stack([c[2] for c in columns]).tolist():
        sheet.append(row)
    meta = book.create_sheet(METADATA_SHEET)
    for key, value in metadata.items():
        meta.append([key, format_header_value(value) if isinstance(value, (list, tuple)) else value])
    with atomic.atomic_path(path) as tmp:
        with open(tmp, "wb") as stream:
            book.save(stream)


register_reader(Reader("excel", read_table, lambda head: head.startswith(ZIP_SIGNATURE), (".xlsx",),
                       {".xlsx": "an Excel .xlsx workbook", ".xls": "an Excel workbook (old .xls workbooks are not "
                                                                     "read: save it as .xlsx or CSV)"}))
register_writer(Writer("xlsx", write_table, ".xlsx", default_for_suffix=True))
