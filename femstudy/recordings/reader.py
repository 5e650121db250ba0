"""The one reader (and writer) of force/torque recordings, whatever file they come in.

:func:`read_recording` takes femstudy's CSV and what acquisition software writes: delimited
text with ``,``, ``;`` or tab, a decimal comma, a byte-order mark, CRLF line ends, a
Kistler-like header block and units row (:mod:`~femstudy.recordings.formats.text`); NI TDMS
(:mod:`~femstudy.recordings.formats.tdms`); MATLAB .mat, v7.3 included
(:mod:`~femstudy.recordings.formats.matlab`); Excel .xlsx
(:mod:`~femstudy.recordings.formats.excel`). The format is told from the file's first bytes,
then its name. Columns are found by name and unit (:mod:`~femstudy.recordings.columns`) and
converted to s, N, N·mm and mm through pint (:mod:`~femstudy.recordings.units`); metadata
are checked against one schema (:mod:`~femstudy.recordings.metadata`).

Required metadata: ``feed_mm_s`` and ``spindle_rpm`` (from the file or the command line).
Defaults: ``drill_diameter_mm = 2.7``, ``point_angle_deg = 90``. Any other key is kept
(synthetic recordings store their effect parameters and ground truth this way), and
``contact_s``/``cut_end_s`` override the automatic isolation of the cut.

Time stamps as data loggers write them are made usable with a note (:func:`daq_time`): an
absolute clock is counted from the first sample, stamps out of order by clock jitter are ordered,
repeated stamps are merged. Every mistake is one :class:`~femstudy.errors.UserError` sentence
naming the file, and the line, row, property or variable where that helps.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from femstudy.drilling.drill import Drill
from femstudy.errors import UserError, require
from femstudy.recordings.columns import assign_channels, parse_column_map
from femstudy.recordings.formats import registry, text
from femstudy.recordings.formats.text import TextStyle
from femstudy.recordings.metadata import check_declared_samples, validate_metadata
from femstudy.recordings.ranges import check_values
from femstudy.recordings.units import QUANTITY_UNITS, factor_to_solver

MIN_RATE_HZ, MAX_RATE_HZ = 100.0, 10_000.0
#: Largest file read: 1 GiB, about 25 million rows of time, thrust and torque
#: (40 minutes at 10 kHz). Longer recordings should be split.
MAX_FILE_BYTES = 1 << 30
MAX_SAMPLES = 25_000_000
_SOLVER_UNIT_WORDS = {"s": "s", "N": "N", "N*mm": "N·mm", "mm": "mm"}


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
                   override_header: bool = False, columns: str | Mapping[str, str] | None = None) -> Recording:
    """Read and check one recording, in s, N, N·mm and mm whatever its file's units.

    Parameters
    ----------
    path : path-like
        A .csv/.tsv/.txt text file, a .tdms, .mat or .xlsx file (told by content, then name).
    overrides : mapping, optional
        Metadata from the command line (``--set``); they must agree with the file's.
    override_header : bool
        Let ``overrides`` win over the file's values (a note says so).
    columns : str or mapping, optional
        Which column is which quantity, e.g. ``"time=Zeit,thrust=Fz[kN],torque=Mz"``
        (``--columns``); it wins over the file's own ``columns`` metadata key.

    Returns
    -------
    Recording
        Arrays in femstudy's units; ``notes`` lists unit conversions and overrides.

    Examples
    --------
    >>> rec = read_recording("run.txt", {"feed_mm_s": 1.5, "spindle_rpm": 1500},
    ...                      columns="time=Zeit[ms],thrust=Fz[kN]")  # doctest: +SKIP
    """
    path = Path(path)
    name = path.name
    require(path.exists(), f"recording {path} does not exist")
    require(not path.is_dir(), f"recording {path} is a folder; give one recording file (only calibrate "
                               f"takes folders of recordings)")
    require(path.is_file(), f"recording {path} is not a file")
    try:
        size = path.stat().st_size
        require(size > 0, f"recording {name} is empty")
        require(size <= MAX_FILE_BYTES, f"recording {name} is {size / 2**30:.1f} GiB; femstudy reads recordings "
                                        f"up to 1 GiB (about 25 million rows): split it")
        table = registry.read_table(path, name)
        metadata, notes = validate_metadata(table.metadata, table.origins, overrides or {}, override_header,
                                            name, table.how_to_add)
        check_declared_samples(metadata, MAX_SAMPLES, name)
        from_file = parse_column_map(metadata.get("columns"), f"recording {name}: metadata columns")
        given = parse_column_map(columns, "--columns")
        notes += [f"--columns {q}={ref.name} overrides the file's {q}={from_file[q].name}"
                  for q, ref in given.items() if q in from_file and from_file[q] != ref]
        channels = assign_channels(table.names, table.units, {**from_file, **given}, name, table.word)
        arrays = table.load([c.index for c in channels])
    except UnicodeDecodeError:
        raise UserError(f"recording {name} is not a text (UTF-8) CSV file") from None
    except OSError as exc:
        raise UserError(f"cannot read recording {path}: {exc.strerror or exc}") from None
    values = {c.quantity: np.asarray(a, dtype=np.float64) * c.factor for c, a in zip(channels, arrays)}
    notes += [f"{c.label} converted from {c.unit} to {_SOLVER_UNIT_WORDS[QUANTITY_UNITS[c.quantity][0]]} "
              f"(x{c.factor:g})" for c in channels if c.factor != 1.0]
    labels = {c.quantity: (c.label, c.unit) for c in channels}
    rec = Recording(time_s=values["time"], thrust_N=values["thrust"], torque_Nmm=values.get("torque"),
                    depth_mm=values.get("depth"), fx_N=values.get("fx"), fy_N=values.get("fy"),
                    metadata=metadata, source=str(path), notes=tuple(notes))
    declared = rec.metadata.get("samples")  # before daq_time merges repeated stamps
    require(declared is None or declared == rec.time_s.size,
            f"recording {name}: the header says samples = {declared} but the file has {rec.time_s.size} data "
            f"rows (truncated?)")
    rec = daq_time(rec)
    check_recording(rec, table.where, labels)
    check_values(rec, table.where, labels)
    return rec


#: A first time stamp this large, and this many times the record's span, is an absolute clock [s].
ABSOLUTE_CLOCK_S = 1e5
ABSOLUTE_CLOCK_SPANS = 1000.0
#: Backward steps shorter than this fraction of the median step are clock jitter, and are ordered.
JITTER_STEPS = 0.5


def daq_time(rec: Recording) -> Recording:
    """Time stamps as data loggers write them, made usable, with one note per change:

    - an absolute clock (the first stamp over ``ABSOLUTE_CLOCK_S`` and ``ABSOLUTE_CLOCK_SPANS``
      times the span, e.g. Unix time): counted from the first sample in float64, so 1.7e9 s + t
      diagnoses as t (``time_origin_s`` in the metadata; ``contact_s``/``cut_end_s`` follow);
    - stamps out of order by less than ``JITTER_STEPS`` of the median step (clock jitter): ordered;
    - repeated stamps (a logger's coarse clock, a buffer written twice): the rows sharing a stamp
      are merged into their mean.

    Anything else (a large backward jump) is left for :func:`check_recording` to refuse."""
    t = np.asarray(rec.time_s, dtype=np.float64)
    if t.size < 3 or not np.all(np.isfinite(t)):  # non-finite stamps are check_recording's to refuse
        return rec
    arrays = {k: getattr(rec, k) for k in ("thrust_N", "torque_Nmm", "depth_mm", "fx_N", "fy_N")}
    notes = list(rec.notes)
    metadata = dict(rec.metadata)
    origin = float(t[0])
    if abs(origin) > ABSOLUTE_CLOCK_S and abs(origin) > ABSOLUTE_CLOCK_SPANS * max(float(t[-1] - t[0]), 1e-9):
        t = t - origin
        metadata["time_origin_s"] = origin
        for key in ("contact_s", "cut_end_s"):
            if isinstance(metadata.get(key), (int, float)) and abs(metadata[key]) > ABSOLUTE_CLOCK_S:
                metadata[key] = float(metadata[key]) - origin
        notes.append(f"time stamps start at {origin:.6f} s (an absolute clock): times are counted from the first sample")
    steps = np.diff(t)
    positive = steps[steps > 0]
    if positive.size and np.any(steps < 0):
        typical = float(np.median(positive))
        back = steps[steps < 0]
        if np.all(-back < JITTER_STEPS * typical):
            order = np.argsort(t, kind="stable")
            t = t[order]
            arrays = {k: None if v is None else np.asarray(v)[order] for k, v in arrays.items()}
            notes.append(f"{back.size} time stamp(s) out of order by less than half a sample (clock jitter) were put in "
                         f"order")
    if np.any(np.diff(t) == 0) and not np.any(np.diff(t) < 0):
        first = np.concatenate([[True], np.diff(t) != 0])
        group = np.cumsum(first) - 1
        counts = np.bincount(group)
        merged = {k: None if v is None else np.bincount(group, weights=np.asarray(v, float)) / counts
                  for k, v in arrays.items()}
        notes.append(f"{int(np.count_nonzero(counts > 1))} repeated time stamp(s) ({int(np.sum(counts[counts > 1]))} rows) "
                     f"were merged, each into the mean of its rows")
        t, arrays = t[first], merged
    if len(notes) == len(rec.notes):
        return rec
    return Recording(time_s=t, metadata=metadata, source=rec.source, notes=tuple(notes), **arrays)


def check_recording(rec: Recording, where: Callable[[int], str] | None = None,
                    columns: Mapping[str, tuple[str, str]] | None = None) -> None:
    """Raise a UserError unless the samples are usable: finite, time strictly increasing (after
    :func:`daq_time`), 100 Hz–10 kHz, longer than one spindle revolution, a thrust that varies.

    ``where(row)`` names a data row in the file's terms ("line 12"); ``columns`` maps a
    quantity to its column's (name, unit) as written, for the messages.
    """
    name = rec.name
    where = where or (lambda row: f"row {row + 1}")
    columns = {**_SOLVER_COLUMNS, **(columns or {})}
    n = rec.time_s.size
    require(n > 0, f"recording {name} has a column line but no data rows")
    require(n <= MAX_SAMPLES, f"recording {name} has {n:,} samples; femstudy reads at most {MAX_SAMPLES:,}: "
                              f"split the recording")
    for quantity, values in (("time", rec.time_s), ("thrust", rec.thrust_N), ("torque", rec.torque_Nmm),
                             ("depth", rec.depth_mm), ("fx", rec.fx_N), ("fy", rec.fy_N)):
        label = columns[quantity][0]
        if values is not None and not np.all(np.isfinite(values)):
            row = int(np.flatnonzero(~np.isfinite(values))[0])
            raise UserError(f"recording {name}: {label} is {values[row]} at {where(row)}; every value "
                            f"must be a finite number")
    require(n >= 3, f"recording {name} has only {n} data rows")
    steps = np.diff(rec.time_s)
    if np.any(steps <= 0):
        row = int(np.flatnonzero(steps <= 0)[0]) + 1
        what = "repeats" if steps[row - 1] == 0 else "goes backwards"
        raise UserError(f"recording {name}: {columns['time'][0]} {what} at {where(row)} ({rec.time_s[row]:g} s after "
                        f"{rec.time_s[row - 1]:g} s); time must increase strictly")
    rate = 1.0 / float(np.median(steps))
    require(MIN_RATE_HZ * 0.99 <= rate <= MAX_RATE_HZ * 1.01,
            f"recording {name} is sampled at {rate:.4g} Hz; femstudy accepts 100 Hz to 10 kHz "
            f"(is {columns['time'][0]} really in {columns['time'][1]}?)")
    revolution = 60.0 / rec.spindle_rpm
    require(rec.duration_s >= revolution,
            f"recording {name} lasts {rec.duration_s:.4g} s, shorter than one spindle revolution "
            f"({revolution:.4g} s at {rec.spindle_rpm:g} rpm)")
    require(np.ptp(rec.thrust_N) > 0, f"recording {name}: {columns['thrust'][0]} is constant "
                                      f"({rec.thrust_N[0]:g} N), so no cut was recorded")


_SOLVER_COLUMNS = {"time": ("time_s", "s"), "thrust": ("thrust_N", "N"), "torque": ("torque_Nmm", "N·mm"),
                   "depth": ("depth_mm", "mm"), "fx": ("fx_N", "N"), "fy": ("fy_N", "N")}


def write_recording(path: str | os.PathLike, rec: Recording, torque_unit: str = "Nmm", *,
                    format: str | TextStyle | None = None, time_unit: str = "s", force_unit: str = "N") -> None:
    """Write ``rec`` in a registered format (atomically), in the units asked for.

    Parameters
    ----------
    path : path-like
        The file to write.
    rec : Recording
        What to write; its metadata go where the format keeps metadata, with ``samples``.
    torque_unit, time_unit, force_unit : str
        Units of the written columns (any unit pint reads: ``N·m``, ``ms``, ``kN``, ``lbf`` ...);
        thrust, fx and fy share ``force_unit``, depth is in mm.
    format : str or TextStyle, optional
        A registered format's name (:func:`femstudy.recordings.formats.registry.writers`), or a
        :class:`TextStyle`; by default from the suffix (.tsv, .txt DynoWare-like, .tdms, .mat,
        .xlsx; anything else CSV).

    Returns
    -------
    None

    Examples
    --------
    >>> write_recording("run.xlsx", rec, "N*m", time_unit="ms")  # doctest: +SKIP
    """
    if isinstance(format, TextStyle):
        write = partial(text.write_table, style=format)
    else:
        write = registry.writer_for(path, format).write
    units = {"time": time_unit, "thrust": force_unit, "torque": torque_unit, "depth": "mm", "fx": force_unit,
             "fy": force_unit}
    columns = []
    for quantity, values in (("time", rec.time_s), ("thrust", rec.thrust_N), ("torque", rec.torque_Nmm),
                             ("depth", rec.depth_mm), ("fx", rec.fx_N), ("fy", rec.fy_N)):
        if values is not None:
            factor = factor_to_solver(units[quantity], quantity, f"the {quantity} column to write")
            columns.append((quantity, units[quantity], np.asarray(values, dtype=float) / factor))
    metadata = {**rec.metadata, "samples": int(rec.time_s.size)}
    write(path, columns, metadata)
