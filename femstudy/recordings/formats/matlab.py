"""MATLAB .mat recordings: v4–v7 through scipy.io, v7.3 (HDF5) through h5py.

Every numeric vector variable is a column, named by the variable (``t``, ``Fz``,
``thrust_N``); its unit is in the name (``thrust_N``, ``time_ms``) or in a struct ``units``
whose fields name the variables (``units.Fz = 'kN'``). Metadata are the scalar and text
variables (``feed_mm_s = 1.5``) and the fields of a struct ``metadata``, which win. Lists
are written as TOML text; MATLAB keeps true/false as 1/0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.errors import UserError, require
from femstudy.recordings.columns import CHANNEL_NAMES
from femstudy.recordings.formats.registry import Reader, Writer, register_reader, register_writer
from femstudy.recordings.formats.table import Table
from femstudy.recordings.metadata import format_header_value, plain_value

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: Largest variable read [elements]: femstudy's limit on samples (25 million) times a few channels.
MAX_VARIABLE_ELEMENTS = 100_000_000
#: MATLAB v7.3 files are HDF5 files behind a 512-byte text header
USER_BLOCK = 512


def is_mat(head: bytes) -> bool:
    """True for the first bytes of a v5–v7.3 MAT-file (v4 files have no signature)."""
    return head.startswith(b"MATLAB ") or head[USER_BLOCK:USER_BLOCK + 8] == HDF5_SIGNATURE


def read_table(path: Path, source: str) -> Table:
    """A .mat recording as a :class:`Table` (see the module docstring)."""
    with path.open("rb") as raw:
        head = raw.read(USER_BLOCK + 8)
    hdf5 = head.startswith(HDF5_SIGNATURE) or head[USER_BLOCK:USER_BLOCK + 8] == HDF5_SIGNATURE
    variables = _read_hdf5(path, source) if hdf5 else _read_classic(path, source)
    columns = {k: v for k, v in variables.items()
               if isinstance(v, np.ndarray) and v.dtype.kind in "fiubc" and v.ndim >= 1 and v.size > 1}
    vectors = [k for k, v in columns.items() if v.ndim == 1 and v.dtype.kind != "c"]
    odd = [k for k in columns if k not in vectors]
    found = ", ".join(f"{k} ({_what(variables[k])})" if k in odd else k for k in variables) or "none"
    hint = "" if not odd else (f"; save the real part of {odd[0]} as a vector" if columns[odd[0]].dtype.kind == "c"
                               else f"; save the columns of {odd[0]} as vectors")
    require(vectors, f"recording {source} (MATLAB) has no numeric vector variables; femstudy needs one per "
                     f"column, e.g. t, Fz and Mz (variables found: {found}){hint}")
    units_struct = variables.get("units") if isinstance(variables.get("units"), dict) else {}
    metadata, origins = {}, {}
    for key, value in variables.items():
        if key not in columns and key not in ("units", "metadata") and _is_scalar(value):
            metadata[key], origins[key] = _metadata_value(value), f"variable {key}"
    nested = variables.get("metadata")
    if isinstance(nested, dict):
        for key, value in nested.items():
            if _is_scalar(value):
                metadata[key], origins[key] = _metadata_value(value), f"variable metadata.{key}"
    names = list(columns)
    units = [str(_metadata_value(units_struct[n])) if n in units_struct else None for n in names]
    return Table(names=names, units=units, metadata=metadata, origins=origins,
                 load=lambda indices: _load(columns, [names[k] for k in indices], source),
                 where=lambda row: f"sample {row + 1}", how_to_add="add a variable {key} (or metadata.{key})",
                 word="variable")


def _what(value: np.ndarray) -> str:
    """What keeps a numeric variable from being a channel: complex values, or a matrix shape."""
    if value.dtype.kind == "c":
        return "complex"
    return f"a {' x '.join(str(n) for n in value.shape)} matrix"


def _load(columns: dict, used: list[str], source: str) -> list[np.ndarray]:
    """The used variables as float vectors: each real and one-dimensional, all of one length."""
    out = []
    for name in used:
        value = columns[name]
        if value.dtype.kind == "c" or value.ndim != 1:
            raise UserError(f"recording {source}: variable {name} is {_what(value)}; femstudy reads each channel "
                            f"as a real vector (save {'its real part' if value.dtype.kind == 'c' else 'its columns as vectors'})")
        out.append(np.asarray(value, dtype=float))
    lengths = {name: len(v) for name, v in zip(used, out)}
    if len(set(lengths.values())) > 1:
        listed = ", ".join(f"{name} {n:,}" for name, n in lengths.items())
        raise UserError(f"recording {source}: its variables differ in length ({listed} samples); every channel "
                        "needs one value per time sample")
    return out


def _is_scalar(value) -> bool:
    if isinstance(value, (str, bytes, int, float, bool, np.generic)):
        return True
    return isinstance(value, np.ndarray) and (value.size <= 1 or value.dtype.kind == "U")


def _metadata_value(value):
    if isinstance(value, np.ndarray) and value.dtype.kind == "U":
        return "".join(value.ravel().tolist())
    return plain_value(value)


def _check_sizes(shapes, source: str) -> None:
    """Refuse a variable whose header announces more than :data:`MAX_VARIABLE_ELEMENTS`
    values, before they are allocated (compressed or unwritten data can claim any size)."""
    for name, shape in shapes:
        elements = int(np.prod([int(n) for n in shape], dtype=float)) if len(shape) else 1
        if elements > MAX_VARIABLE_ELEMENTS:
            raise UserError(f"recording {source}: variable {name} announces {elements:,} values "
                            f"({' x '.join(str(n) for n in shape)}); femstudy reads at most {MAX_VARIABLE_ELEMENTS:,} "
                            "per variable: split the recording")


def _read_classic(path: Path, source: str) -> dict:
    import scipy.io

    try:
        _check_sizes([(name, shape) for name, shape, _ in scipy.io.whosmat(path)], source)
    except UserError:
        raise
    except Exception:  # noqa: BLE001 - a damaged file: loadmat below reports it
        pass
    try:
        data = scipy.io.loadmat(path, squeeze_me=True, simplify_cells=True)
    except Exception as exc:  # scipy raises ValueError, TypeError, MatReadError ... on a damaged file
        raise UserError(f"recording {source} is not a readable MATLAB .mat file ({type(exc).__name__}: "
                        f"{exc})") from None
    return {k: v for k, v in data.items() if not k.startswith("__")}


def _read_hdf5(path: Path, source: str) -> dict:
    """Variables of a v7.3 MAT-file: numeric arrays, text, and structs as dicts."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            shapes = []
            f.visititems(lambda name, node: shapes.append((name, node.shape))
                         if isinstance(node, h5py.Dataset) and node.shape is not None else None)
            _check_sizes(shapes, source)
            return {name: value for name, value in ((n, _hdf5_variable(f[n])) for n in f if not n.startswith("#"))
                    if value is not None}
    except (OSError, KeyError, ValueError) as exc:
        raise UserError(f"recording {source} is not a readable MATLAB v7.3 .mat file ({exc})") from None


def _hdf5_variable(node):
    import h5py

    matlab_class = node.attrs.get("MATLAB_class", b"")
    matlab_class = matlab_class.decode() if isinstance(matlab_class, bytes) else str(matlab_class)
    if isinstance(node, h5py.Group):
        if matlab_class != "struct":
            return None
        return {k: v for k, v in ((k, _hdf5_variable(node[k])) for k in node) if v is not None}
    names = node.dtype.names or ()
    if node.dtype.kind == "V" and {"real", "imag"} <= set(names):  # MATLAB's complex: a compound
        raw = np.asarray(node[()])
        return _shaped(raw["real"] + 1j * raw["imag"])
    if node.dtype.kind not in "fiub":
        return None  # cell arrays (references), other compound types: not used
    if node.attrs.get("MATLAB_empty", 0):
        return "" if matlab_class == "char" else np.empty(0)
    values = _shaped(np.asarray(node[()]))
    if matlab_class == "char":
        return "".join(chr(c) for c in values.ravel())
    if values.size == 1:
        return bool(values.ravel()[0]) if matlab_class == "logical" else values.ravel()[0].item()
    return values


def _shaped(values: np.ndarray) -> np.ndarray:
    """A MATLAB array as a vector when it is one (1 x n or n x 1), else as it is."""
    return values.ravel() if values.ndim <= 1 or sum(n > 1 for n in values.shape) <= 1 else values


# -- writing ----------------------------------------------------------------------------------

def _variables(columns, metadata: dict) -> tuple[dict, dict, dict]:
    """(channel vectors, their units, metadata) as MATLAB variables; lists as TOML text."""
    vectors = {CHANNEL_NAMES[q]: np.asarray(v, dtype=float) for q, _, v in columns}
    units = {CHANNEL_NAMES[q]: u for q, u, _ in columns}
    meta = {k: format_header_value(v) if isinstance(v, (list, tuple)) else v for k, v in metadata.items()}
    return vectors, units, meta


def write_table(path, columns: list[tuple[str, str, np.ndarray]], metadata: dict) -> None:
    """Write a v5 MAT-file: vectors ``Time``, ``Fz``, ``Mz`` ..., a struct ``units`` naming
    their units and a struct ``metadata`` (atomically)."""
    import scipy.io

    vectors, units, meta = _variables(columns, metadata)
    with atomic.atomic_path(path) as tmp:
        with open(tmp, "wb") as stream:
            scipy.io.savemat(stream, {**vectors, "units": units, "metadata": meta}, oned_as="column")


def write_table_v73(path, columns: list[tuple[str, str, np.ndarray]], metadata: dict) -> None:
    """Write the same variables as a MATLAB v7.3 (HDF5) MAT-file with h5py (atomically)."""
    import h5py

    vectors, units, meta = _variables(columns, metadata)
    with atomic.atomic_path(path) as tmp:
        with h5py.File(tmp, "w", userblock_size=USER_BLOCK) as f:
            for name, values in vectors.items():
                f.create_dataset(name, data=values.reshape(1, -1)).attrs["MATLAB_class"] = np.bytes_("double")
            for struct_name, fields in (("units", units), ("metadata", meta)):
                group = f.create_group(struct_name)
                group.attrs["MATLAB_class"] = np.bytes_("struct")
                for key, value in fields.items():
                    _write_hdf5_value(group, key, value)
        header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: femstudy HDF5 schema 1.00 ."
        with open(tmp, "r+b") as stream:
            stream.write(header.ljust(116) + b"\x00" * 8 + b"\x00\x02" + b"IM" + b"\x00" * (USER_BLOCK - 128))


def _write_hdf5_value(group, key: str, value) -> None:
    if isinstance(value, str):
        codes = np.array([ord(c) for c in value], dtype=np.uint16).reshape(-1, 1)
        if codes.size == 0:
            dataset = group.create_dataset(key, data=np.zeros(2, dtype=np.uint64))
            dataset.attrs["MATLAB_empty"] = np.uint8(1)
        else:
            dataset = group.create_dataset(key, data=codes)
        dataset.attrs["MATLAB_class"] = np.bytes_("char")
    elif isinstance(value, bool):
        group.create_dataset(key, data=np.array([[value]], dtype=np.uint8)).attrs["MATLAB_class"] = \
            np.bytes_("logical")
    elif isinstance(value, (int, np.integer)):
        group.create_dataset(key, data=np.array([[value]], dtype=np.int64)).attrs["MATLAB_class"] = \
            np.bytes_("int64")
    else:
        group.create_dataset(key, data=np.array([[float(value)]])).attrs["MATLAB_class"] = np.bytes_("double")


register_reader(Reader("matlab", read_table, lambda head: is_mat(head) or head.startswith(HDF5_SIGNATURE), (".mat",),
                       {".mat": None}))
register_writer(Writer("mat", write_table, ".mat", default_for_suffix=True))
register_writer(Writer("mat73", write_table_v73, ".mat"))
