"""The registry of recording file formats: each format module registers its reader and writers.

A reader is tried when it recognises a file's first bytes (and name); the delimited-text
reader, which recognises no signature, reads whatever no other reader claims. A writer is one
named way to write a recording (several text styles share the text module). A new format is
one module in :mod:`femstudy.recordings.formats` that calls :func:`register_reader` and
:func:`register_writer`; every module there is imported when the registry is first read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from femstudy.errors import UserError, require
from femstudy.recordings.formats.table import Table


@dataclass(frozen=True)
class Reader:
    """One format's reader.

    name : the format ("text", "tdms", "matlab", "excel")
    read : ``read(path, source) -> Table``
    recognises : ``recognises(head) -> bool`` from the file's first :data:`HEAD_BYTES` bytes;
        None for the fallback reader (delimited text), which reads what no other reader claims
    suffixes : what a folder of recordings may hold in this format
    by_name : lower-case suffix → None (a file of that name is read by this reader whatever
        its first bytes: MATLAB v4 files have no signature) or the words for a file whose name
        claims the format but whose content is not it ("a TDMS file")
    """

    name: str
    read: Callable[[Path, str], Table]
    recognises: Callable[[bytes], bool] | None
    suffixes: tuple[str, ...] = ()
    by_name: dict[str, str | None] = field(default_factory=dict)


@dataclass(frozen=True)
class Writer:
    """One named way to write a recording: ``write(path, columns, metadata)`` (columns as
    (quantity, unit, values)), the file suffix it goes with, and whether a file of that suffix is
    written this way when no format is named."""

    name: str
    write: Callable
    suffix: str
    default_for_suffix: bool = False


#: Bytes of a file's head that readers recognise it by (a MATLAB v7.3 file's HDF5 signature
#: follows a 512-byte user block).
HEAD_BYTES = 520

_READERS: dict[str, Reader] = {}
_WRITERS: dict[str, Writer] = {}


def register_reader(reader: Reader) -> Reader:
    require(reader.name not in _READERS, f"a recording reader named '{reader.name}' is already registered")
    _READERS[reader.name] = reader
    return reader


def register_writer(writer: Writer) -> Writer:
    require(writer.name not in _WRITERS, f"a recording format named '{writer.name}' is already registered")
    _WRITERS[writer.name] = writer
    return writer


def _discover() -> None:
    import femstudy.recordings.formats  # noqa: F401  (its import registers every format module)


def readers() -> tuple[Reader, ...]:
    _discover()
    return tuple(_READERS.values())


def writers() -> dict[str, Writer]:
    """Every writer by name, in registration order."""
    _discover()
    return dict(_WRITERS)


def recording_suffixes() -> tuple[str, ...]:
    """The file suffixes a folder of recordings may hold (delimited text's first)."""
    ordered = sorted(readers(), key=lambda r: r.recognises is not None)
    return tuple(dict.fromkeys(s for r in ordered for s in r.suffixes))


def read_table(path: Path, source: str) -> Table:
    """The table of ``path`` read by the reader that recognises its first bytes, else by the one
    its name calls for, else by the fallback reader; a name that claims a format the content is
    not is refused."""
    with path.open("rb") as raw:
        head = raw.read(HEAD_BYTES)
    suffix = path.suffix.lower()
    every = readers()
    for reader in every:
        if reader.recognises is not None and reader.recognises(head):
            return reader.read(path, source)
    for reader in every:
        if suffix in reader.by_name:
            words = reader.by_name[suffix]
            if words is None:
                return reader.read(path, source)
            raise UserError(f"recording {source} has a {suffix} name but is not {words}")
    return next(r for r in every if r.recognises is None).read(path, source)


def writer_for(path: str | Path, name: str | None = None) -> Writer:
    """The writer called ``name``, else the default one for the file's suffix, else CSV."""
    every = writers()
    if name is None:
        suffix = Path(path).suffix.lower()
        name = next((w.name for w in every.values() if w.default_for_suffix and w.suffix == suffix), "csv")
    require(name in every, f"unknown recording format '{name}'; choose one of {', '.join(every)}")
    return every[name]
