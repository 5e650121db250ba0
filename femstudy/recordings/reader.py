"""The one reader (and writer) of force/torque recordings.

A recording is a CSV file. Optional metadata come first as comment lines ``# key = value``
whose values are TOML (``# feed_mm_s = 1.5``, ``# specimen = "bovine femur 3"``); other
comment lines are free text. The first non-comment line names the columns, each with its
unit: ``time_s`` and ``thrust_N`` are required; ``torque_Nmm`` or ``torque_Nm`` (converted
to N·mm, ×1000), ``depth_mm``, ``fx_N`` and ``fy_N`` are optional; unknown columns are
ignored. Sampling between 100 Hz and 10 kHz, uneven sampling allowed.

Required metadata: ``feed_mm_s`` and ``spindle_rpm`` (from the header or the command line).
Defaults: ``drill_diameter_mm = 2.7``, ``point_angle_deg = 90``. Any other key is kept
(synthetic recordings store their effect parameters and ground truth this way), and
``contact_s``/``cut_end_s`` override the automatic isolation of the cut.

Every mistake is one :class:`~femstudy.errors.UserError` sentence naming the file, and the
line where that helps. Values given on the command line must agree with the header unless
``override_header`` is set; then the command line wins and a note says so.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from femstudy import atomic
from femstudy.drilling.drill import Drill
from femstudy.errors import UserError, require

MIN_RATE_HZ, MAX_RATE_HZ = 100.0, 10_000.0
#: Largest file read: 1 GiB, about 25 million rows of time, thrust and torque
#: (40 minutes at 10 kHz). Longer recordings should be split.
MAX_FILE_BYTES = 1 << 30
MAX_HEADER_BYTES = 64 * 1024
MAX_SAMPLES = 25_000_000

#: Accepted columns: quantity -> {unit suffix: factor to femstudy's unit}.
COLUMN_UNITS = {
    "time": {"s": 1.0},
    "thrust": {"N": 1.0},
    "torque": {"Nmm": 1.0, "Nm": 1000.0},
    "depth": {"mm": 1.0},
    "fx": {"N": 1.0},
    "fy": {"N": 1.0},
}
UNIT_WORDS = {"s": "seconds", "N": "newtons", "Nmm": "N·mm", "Nm": "N·m", "mm": "millimetres"}
REQUIRED_COLUMNS = ("time", "thrust")


class RecordingMetadata(BaseModel):
    """Header keys femstudy interprets; any other key is kept as given."""

    model_config = ConfigDict(extra="allow", frozen=True)

    feed_mm_s: float = Field(gt=0, le=50, allow_inf_nan=False)
    spindle_rpm: float = Field(gt=0, le=100_000, allow_inf_nan=False)
    drill_diameter_mm: float = Field(2.7, gt=0, le=20, allow_inf_nan=False)
    point_angle_deg: float = Field(90.0, gt=0, lt=180)
    specimen: str = ""
    samples: int | None = Field(None, ge=0)
    contact_s: float | None = Field(None, allow_inf_nan=False)
    cut_end_s: float | None = Field(None, allow_inf_nan=False)


@dataclass(frozen=True)
class Recording:
    """Thrust [N] and torque [N·mm] against time [s], with the header's metadata.

    ``torque_Nmm``, ``depth_mm``, ``fx_N`` and ``fy_N`` are None when the file has no such
    column. ``notes`` lists unit conversions and command-line overrides.
    """

    time_s: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray | None = None
    depth_mm: np.ndarray | None = None
    fx_N: np.ndarray | None = None
    fy_N: np.ndarray | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict)
    source: str = "<memory>"
    notes: tuple[str, ...] = ()

    @property
    def feed_mm_s(self) -> float:
        return float(self.metadata["feed_mm_s"])

    @property
    def spindle_rpm(self) -> float:
        return float(self.metadata["spindle_rpm"])

    @property
    def drill(self) -> Drill:
        """The drill of the header (diameter and point angle; other lengths at their defaults)."""
        return Drill(diameter_mm=float(self.metadata.get("drill_diameter_mm", 2.7)),
                     point_angle_deg=float(self.metadata.get("point_angle_deg", 90.0)))

    @property
    def sample_rate_hz(self) -> float:
        """1 / median time step [Hz]."""
        return float(1.0 / np.median(np.diff(self.time_s)))

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def name(self) -> str:
        return Path(self.source).name


def read_recording(path: str | os.PathLike, overrides: Mapping[str, Any] | None = None,
                   override_header: bool = False) -> Recording:
    """Read and check one recording; ``overrides`` are metadata from the command line."""
    path = Path(path)
    name = path.name
    require(path.exists(), f"recording {path} does not exist")
    require(path.is_file(), f"recording {path} is not a file")
    size = path.stat().st_size
    require(size > 0, f"recording {name} is empty")
    require(size <= MAX_FILE_BYTES, f"recording {name} is {size / 2**30:.1f} GiB; femstudy reads "
                                    f"recordings up to 1 GiB (about 25 million rows): split it")
    with path.open("rb") as raw:
        require(b"\x00" not in raw.read(4096), f"recording {name} is not a text (UTF-8) CSV file")
    try:
        with path.open("r", encoding="utf-8", newline="") as stream:
            header, columns, first_data_line = _read_header(stream, name)
            if columns is None:
                raise UserError(f"recording {name} has no column line (expected e.g. "
                                f"'time_s,thrust_N,torque_Nmm' after the '#' metadata lines)")
            metadata, notes = _metadata(header, overrides or {}, override_header, name)
            quantity_of, factors = _parse_columns(columns, name)
            if metadata.get("samples") and metadata["samples"] > MAX_SAMPLES:
                raise UserError(f"recording {name}: the header claims {metadata['samples']:,} samples; "
                                f"femstudy reads at most {MAX_SAMPLES:,}: split the recording")
            usecols = sorted(quantity_of)
            data = _read_numbers(stream, usecols, name, path, first_data_line)
    except UnicodeDecodeError:
        raise UserError(f"recording {name} is not a text (UTF-8) CSV file") from None
    except OSError as exc:
        raise UserError(f"cannot read recording {path}: {exc.strerror or exc}") from None

    arrays = {quantity_of[c]: data[:, k] * factors[c] for k, c in enumerate(usecols)}
    for c in usecols:
        if factors[c] != 1.0:
            notes.append(f"{columns[c]} converted to N·mm (x{factors[c]:g})")
    rec = Recording(time_s=arrays["time"], thrust_N=arrays["thrust"], torque_Nmm=arrays.get("torque"),
                    depth_mm=arrays.get("depth"), fx_N=arrays.get("fx"), fy_N=arrays.get("fy"),
                    metadata=metadata, source=str(path), notes=tuple(notes))
    check_recording(rec, lambda row: _line_of_row(path, first_data_line, row))
    return rec


def check_recording(rec: Recording, line_of=None) -> None:
    """Raise a UserError unless the samples are usable: finite, time strictly increasing,
    100 Hz–10 kHz, longer than one spindle revolution, a thrust that varies."""
    name = rec.name
    where = (lambda row: f"line {line_of(row)}") if line_of else (lambda row: f"row {row + 1}")
    n = rec.time_s.size
    require(n > 0, f"recording {name} has a column line but no data rows")
    for label, values in (("time_s", rec.time_s), ("thrust_N", rec.thrust_N), ("torque", rec.torque_Nmm),
                          ("depth_mm", rec.depth_mm), ("fx_N", rec.fx_N), ("fy_N", rec.fy_N)):
        if values is not None and not np.all(np.isfinite(values)):
            row = int(np.flatnonzero(~np.isfinite(values))[0])
            raise UserError(f"recording {name}: {label} is {values[row]} at {where(row)}; every value "
                            f"must be a finite number")
    declared = rec.metadata.get("samples")
    require(declared is None or declared == n,
            f"recording {name}: the header says samples = {declared} but the file has {n} data "
            f"rows (truncated?)")
    require(n >= 3, f"recording {name} has only {n} data rows")
    steps = np.diff(rec.time_s)
    if np.any(steps <= 0):
        row = int(np.flatnonzero(steps <= 0)[0]) + 1
        what = "repeats" if steps[row - 1] == 0 else "goes backwards"
        raise UserError(f"recording {name}: time_s {what} at {where(row)} ({rec.time_s[row]:g} s after "
                        f"{rec.time_s[row - 1]:g} s); time must increase strictly")
    rate = 1.0 / float(np.median(steps))
    require(MIN_RATE_HZ * 0.99 <= rate <= MAX_RATE_HZ * 1.01,
            f"recording {name} is sampled at {rate:.4g} Hz; femstudy accepts 100 Hz to 10 kHz "
            f"(is time_s really in seconds?)")
    revolution = 60.0 / rec.spindle_rpm
    require(rec.duration_s >= revolution,
            f"recording {name} lasts {rec.duration_s:.4g} s, shorter than one spindle revolution "
            f"({revolution:.4g} s at {rec.spindle_rpm:g} rpm)")
    require(np.ptp(rec.thrust_N) > 0, f"recording {name}: thrust_N is constant "
                                      f"({rec.thrust_N[0]:g} N), so no cut was recorded")


def _read_header(stream, name: str) -> tuple[list[tuple[int, str]], list[str] | None, int]:
    """Metadata lines (number, text) and the column names; leaves ``stream`` at the data."""
    header, size, number = [], 0, 0
    for line in stream:
        number += 1
        size += len(line)
        if size > MAX_HEADER_BYTES:
            raise UserError(f"recording {name}: the header is longer than {MAX_HEADER_BYTES // 1024} kB "
                            f"before the column line; is this a recording?")
        text = line.strip()
        if not text:
            continue
        if text.startswith("#"):
            header.append((number, text[1:].strip()))
            continue
        return header, [c.strip() for c in text.split(",")], number + 1
    return header, None, number + 1


_KEY_LINE = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*\s*=")


def _metadata(header, overrides: Mapping[str, Any], override_header: bool, name: str):
    """Header values, command-line values, and the validated combination."""
    values: dict[str, Any] = {}
    for number, text in header:
        if not _KEY_LINE.match(text):
            continue  # a free-text comment
        try:
            values.update(tomllib.loads(text))
        except tomllib.TOMLDecodeError as exc:
            raise UserError(f"recording {name}, line {number}: '# {text}' is not 'key = value' with a "
                            f"TOML value ({exc}); quote text values") from None
    notes = []
    for key, value in overrides.items():
        if key in values and not _same(values[key], value):
            if not override_header:
                raise UserError(f"recording {name}: its header says {key} = {_show(values[key])} but the "
                                f"command line says {_show(value)}; remove one of them, or pass "
                                f"--override to let the command line win")
            notes.append(f"{key} = {_show(value)} from the command line overrides "
                         f"{_show(values[key])} in the header")
        values[key] = value
    for key in ("feed_mm_s", "spindle_rpm"):
        require(key in values, f"recording {name} has no {key}: add '# {key} = ...' to its header or "
                               f"give it on the command line (--set {key}=...)")
    try:
        model = RecordingMetadata(**values)
    except ValidationError as exc:
        err = exc.errors()[0]
        key = ".".join(str(p) for p in err["loc"])
        raise UserError(f"recording {name}: metadata {key} = {_show(values.get(key))} is invalid: "
                        f"{err['msg'].lower()}") from None
    merged = {**values, **model.model_dump(exclude_none=True)}
    return merged, notes


def _same(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return a == b


def _show(value) -> str:
    return json.dumps(value) if isinstance(value, str) else repr(value)


def _parse_columns(columns: list[str], name: str) -> tuple[dict[int, str], dict[int, float]]:
    """Map column index -> quantity and unit factor; explain unit-less or unknown units."""
    quantity_of, factors, seen = {}, {}, {}
    for index, column in enumerate(columns):
        quantity, _, unit = column.partition("_")
        base = quantity.lower()
        if base not in COLUMN_UNITS:
            continue  # an extra column, ignored
        accepted = " or ".join(f"{base}_{u} ({UNIT_WORDS[u]})" for u in COLUMN_UNITS[base])
        if not unit:
            raise UserError(f"recording {name}: column '{column}' has no unit; name it {accepted}")
        if unit not in COLUMN_UNITS[base]:
            raise UserError(f"recording {name}: column '{column}' has unit '{unit}', which femstudy does "
                            f"not convert; name it {accepted}")
        if base in seen:
            raise UserError(f"recording {name} has two {base} columns ('{seen[base]}' and '{column}')")
        seen[base] = column
        quantity_of[index], factors[index] = base, COLUMN_UNITS[base][unit]
    for base in REQUIRED_COLUMNS:
        if base not in seen:
            unit = next(iter(COLUMN_UNITS[base]))
            raise UserError(f"recording {name} has no {base}_{unit} column ({UNIT_WORDS[unit]}); its "
                            f"columns are: {', '.join(columns) or 'none'}")
    return quantity_of, factors


def _read_numbers(stream, usecols: list[int], name: str, path: Path, first_line: int) -> np.ndarray:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": checked later
            data = np.loadtxt(stream, delimiter=",", usecols=usecols, ndmin=2, comments="#")
    except ValueError:
        raise UserError(_first_bad_line(path, first_line, usecols, name)) from None
    return data


def _first_bad_line(path: Path, first_line: int, usecols: list[int], name: str) -> str:
    """Locate the first data line that is not a row of numbers (slow path, errors only)."""
    with path.open("r", encoding="utf-8") as stream:
        for number, line in enumerate(stream, start=1):
            text = line.strip()
            if number < first_line or not text or text.startswith("#"):
                continue
            fields = [f.strip() for f in text.split(",")]
            if len(fields) <= max(usecols):
                return f"recording {name}, line {number}: {len(fields)} values, expected one per column"
            for k in usecols:
                try:
                    float(fields[k])
                except ValueError:
                    shown = fields[k] or "an empty field"
                    return f"recording {name}, line {number}: {shown!s} in column {k + 1} is not a number"
    return f"recording {name}: the data rows do not all have the same number of values"


def _line_of_row(path: Path, first_line: int, row: int) -> int:
    """1-based line number of data row ``row`` (skipping blank and comment lines)."""
    seen = -1
    with path.open("r", encoding="utf-8") as stream:
        for number, line in enumerate(stream, start=1):
            text = line.strip()
            if number < first_line or not text or text.startswith("#"):
                continue
            seen += 1
            if seen == row:
                return number
    return first_line + row


def format_header_value(value) -> str:
    """A Python value as a TOML value for a ``# key = value`` line."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if math.isfinite(value) else ("nan" if math.isnan(value) else
                                                                ("inf" if value > 0 else "-inf"))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_header_value(v) for v in value) + "]"
    return json.dumps(str(value))


def write_recording(path: str | os.PathLike, rec: Recording, torque_unit: str = "Nmm") -> None:
    """Write ``rec`` in the recording format (atomically); torque in N·mm or N·m."""
    require(torque_unit in ("Nmm", "Nm"), f"torque unit must be Nmm or Nm, got '{torque_unit}'")
    columns = [("time_s", rec.time_s, "%.9g"), ("thrust_N", rec.thrust_N, "%.6g")]
    if rec.torque_Nmm is not None:
        scale = 1.0 if torque_unit == "Nmm" else 1e-3
        columns.append((f"torque_{torque_unit}", rec.torque_Nmm * scale, "%.6g"))
    for label, values in (("depth_mm", rec.depth_mm), ("fx_N", rec.fx_N), ("fy_N", rec.fy_N)):
        if values is not None:
            columns.append((label, values, "%.6g"))
    meta = {**rec.metadata, "samples": int(rec.time_s.size)}
    buf = io.StringIO()
    for key, value in meta.items():
        buf.write(f"# {key} = {format_header_value(value)}\n")
    buf.write(",".join(c[0] for c in columns) + "\n")
    np.savetxt(buf, np.column_stack([c[1] for c in columns]), delimiter=",",
               fmt=[c[2] for c in columns])
    atomic.write_text(path, buf.getvalue())
