"""NI TDMS recordings (LabVIEW, DAQmx, FlexLogger), read and written with npTDMS.

Channels are the columns: their names (``Fz``, ``Mz``, ``Time``; ``group/channel`` when two
groups share a name) and their ``unit_string`` property, NI's place for a unit. Without a
time channel the time comes from the waveform properties ``wf_start_offset`` and
``wf_increment`` (in ``wf_xunit_string``, default s) of the thrust channel or, failing that,
the first channel. Metadata are the file's properties, then each group's (a group's
property wins). Lists, which TDMS properties cannot hold, are written as TOML text.
"""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.errors import UserError, require
from femstudy.recordings.columns import CHANNEL_NAMES, quantity_of, split_name
from femstudy.recordings.formats.registry import Reader, Writer, register_reader, register_writer
from femstudy.recordings.formats.table import Table
from femstudy.recordings.metadata import format_header_value, plain_value

MAGIC = b"TDSm"
GROUP = "recording"


@contextlib.contextmanager
def quiet_nptdms():
    """Silence npTDMS's own warnings (it sets its loggers' levels itself): a damaged segment
    is reported by femstudy in one line (channels of different lengths, a truncated file)."""
    loggers = [logging.getLogger(name) for name in list(logging.root.manager.loggerDict) if name.startswith("nptdms")]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels):
            logger.setLevel(level)


def read_table(path: Path, source: str) -> Table:
    """A TDMS recording as a :class:`Table` (see the module docstring)."""
    from nptdms import TdmsFile

    try:
        with quiet_nptdms():
            tdms = TdmsFile.read(path)
    except Exception as exc:  # npTDMS raises ValueError, KeyError, struct.error ... on a damaged file
        raise UserError(f"recording {source} is not a readable TDMS file ({type(exc).__name__}: {exc})") from None
    channels = [channel for group in tdms.groups() for channel in group.channels()]
    require(channels, f"recording {source} (TDMS) has no channels")
    short = [c.name for c in channels]
    names = [c.name if short.count(c.name) == 1 else f"{c.group_name}/{c.name}" for c in channels]
    units = [str(c.properties.get("unit_string", "")).strip() or None for c in channels]
    arrays = {k: (lambda c=c: c[:]) for k, c in enumerate(channels)}
    if not any(quantity_of(split_name(n)[0]) == "time" for n in names):
        timed = [c for c in channels if "wf_increment" in c.properties]
        thrust = [c for c, n in zip(channels, names) if quantity_of(split_name(n)[0]) == "thrust"]
        timed = [c for c in thrust if c in timed] + timed
        if timed:
            names.append("time")
            units.append(str(timed[0].properties.get("wf_xunit_string", "")).strip() or "s")
            arrays[len(names) - 1] = timed[0].time_track
    metadata, origins = {}, {}
    for key, value in tdms.properties.items():
        metadata[key], origins[key] = _value(value), f"file property {key}"
    for group in tdms.groups():
        for key, value in group.properties.items():
            metadata[key], origins[key] = _value(value), f"group '{group.name}' property {key}"
    return Table(names=names, units=units, metadata=metadata, origins=origins,
                 load=lambda indices: _load(arrays, names, indices, source),
                 where=lambda row: f"sample {row + 1}", how_to_add="add the file property {key}", word="channel")


def _value(value):
    if isinstance(value, np.datetime64):
        return str(value)
    return plain_value(value)


def _load(arrays, names, indices: list[int], source: str) -> list[np.ndarray]:
    out = [np.asarray(arrays[k](), dtype=float) for k in indices]
    sizes = {names[k]: a.size for k, a in zip(indices, out)}
    require(len(set(sizes.values())) <= 1,
            f"recording {source}: its channels differ in length (" +
            ", ".join(f"'{n}' {s} samples" for n, s in sizes.items()) + "); femstudy needs one sample of each "
            "per time step (is the file truncated?)")
    return out


def write_table(path, columns: list[tuple[str, str, np.ndarray]], metadata: dict) -> None:
    """Write (quantity, unit, values) columns as channels ``Time``, ``Fz``, ``Mz`` ... with
    ``unit_string`` properties in one group, and the metadata as file properties (atomically)."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    properties = {key: format_header_value(value) if isinstance(value, (list, tuple)) else value
                  for key, value in metadata.items()}
    objects = [RootObject(properties=properties), GroupObject(GROUP)]
    objects += [ChannelObject(GROUP, CHANNEL_NAMES[quantity], np.asarray(values, dtype=float),
                              properties={"unit_string": unit}) for quantity, unit, values in columns]
    with atomic.atomic_path(path) as tmp:
        with open(tmp, "wb") as stream, TdmsWriter(stream) as writer:
            writer.write_segment(objects)


register_reader(Reader("tdms", read_table, lambda head: head.startswith(MAGIC), (".tdms",),
                       {".tdms": "a TDMS file"}))
register_writer(Writer("tdms", write_table, ".tdms", default_for_suffix=True))
