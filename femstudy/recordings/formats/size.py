"""How many samples a recording file holds, told from its bytes and headers without reading
its values, so that a command can refuse a recording too long for it before any work.

Text: the line count (a 1 GiB file is counted in about a second). MATLAB: the variables'
shapes (scipy's ``whosmat``, h5py's dataset shapes). TDMS: the channels' lengths from the
file's metadata. Excel: the rows its sheets' XML can hold (a worksheet's ``dimension`` may
claim anything; femstudy reads the cells themselves, see
:mod:`femstudy.recordings.formats.excel`).
"""

from __future__ import annotations

from pathlib import Path

from femstudy.errors import UserError

#: Longest recording that diagnose and calibrate analyse [samples]: their fits and noise models
#: grow faster than the samples (diagnose took 9 s for 150,000, 22 s for 550,000 and 134 s for
#: 1,050,000 samples of a synthetic 10 kHz recording on the 2-core machine), and a cut lasts
#: seconds. Longer recordings are refused before they are read, with the advice to crop them.
MAX_ANALYSED_SAMPLES = 1_000_000
#: Fewest bytes a spreadsheet row of two numbers takes in a worksheet's XML.
XLSX_BYTES_PER_ROW = 40


def _text_lines(path: Path) -> int:
    lines = 0
    with open(path, "rb") as stream:
        for chunk in iter(lambda: stream.read(1 << 24), b""):
            lines += chunk.count(b"\n")
    return lines


def _mat_samples(path: Path) -> int:
    from femstudy.recordings.formats import matlab

    with open(path, "rb") as raw:
        head = raw.read(matlab.USER_BLOCK + 8)
    if head.startswith(matlab.HDF5_SIGNATURE) or head[matlab.USER_BLOCK:matlab.USER_BLOCK + 8] == matlab.HDF5_SIGNATURE:
        import h5py

        sizes = []
        with h5py.File(path, "r") as f:
            f.visititems(lambda _, node: sizes.append(node.size) if isinstance(node, h5py.Dataset) else None)
        return max(sizes, default=0)
    import scipy.io

    return max((int(_prod(shape)) for _, shape, _ in scipy.io.whosmat(path)), default=0)


def _prod(shape) -> int:
    out = 1
    for n in shape:
        out *= int(n)
    return out


def _tdms_samples(path: Path) -> int:
    from nptdms import TdmsFile

    from femstudy.recordings.formats.tdms import quiet_nptdms

    with quiet_nptdms():
        meta = TdmsFile.read_metadata(path)
    return max((len(channel) for group in meta.groups() for channel in group.channels()), default=0)


def _xlsx_samples(path: Path) -> int:
    import zipfile

    with zipfile.ZipFile(path) as book:
        sheets = [i.file_size for i in book.infolist() if i.filename.startswith("xl/worksheets/")]
    return max(sheets, default=0) // XLSX_BYTES_PER_ROW


def recording_samples(path: str | Path) -> int | None:
    """An upper bound on the samples of one channel of a recording file, or None when its
    format cannot be told (the reader then says why)."""
    from femstudy.recordings.formats import excel, matlab, tdms

    path = Path(path)
    try:
        with open(path, "rb") as raw:
            head = raw.read(matlab.USER_BLOCK + 8)
        if head.startswith(tdms.MAGIC):
            return _tdms_samples(path)
        if head.startswith(excel.ZIP_SIGNATURE):
            return _xlsx_samples(path)
        if matlab.is_mat(head) or head.startswith(matlab.HDF5_SIGNATURE) or path.suffix.lower() == ".mat":
            return _mat_samples(path)
        return _text_lines(path)
    except Exception:  # noqa: BLE001 - a damaged file: the reader reports it properly
        return None


def check_recording_size(path: str | Path, limit: int, command: str) -> None:
    """Refuse, before it is read, a recording with more than ``limit`` samples for ``command``."""
    path = Path(path)
    if not path.is_file():
        return  # the reader says what is wrong with it
    samples = recording_samples(path)
    if samples is not None and samples > limit:
        raise UserError(f"recording {path.name} holds about {samples:,} samples; {command} takes recordings of up to "
                        f"{limit:,} (100 s at 10 kHz): crop it to the cut, or resample it")
