"""Convert femur surfaces of the msk-STAPLE bone datasets (MATLAB ``triangulation`` objects
in ``.mat`` files) to binary STL, for bench/frame_poses.py and the frame tests.

A ``triangulation`` object is saved in the MAT file's subsystem data (MATLAB's class-object
store), which ``scipy.io.loadmat`` returns as raw bytes (``__function_workspace__``). Those
bytes are themselves a version-5 MAT stream without the text header; read with scipy's MAT
reader they hold the object's properties, among them the points (n × 3 doubles) and the
1-based connectivity list (m × 3 whole numbers). scipy has no public call for this, so the
reader class is imported from ``scipy.io.matlab._mio5``.

    git -C <msk-STAPLE clone> show HEAD:bone_datasets/LHDL_CT/tri/femur_r.mat > LHDL_CT_femur_r.mat
    python bench/staple_femurs.py LHDL_CT_femur_r.mat ... --out ../femurs

Each ``<dataset>_femur_<side>.mat`` becomes ``<out>/<dataset>_femur_<side>.stl``; the
licence of every dataset is in docs/meshing.md. Nothing converted belongs in the repository.
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path

import numpy as np


def triangulation_arrays(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) and 0-based triangles (m, 3) of the triangulation saved in ``path``."""
    import scipy.io
    from scipy.io.matlab._mio5 import MatFile5Reader

    store = scipy.io.loadmat(path)["__function_workspace__"].tobytes()
    # a MAT header: 116 bytes of text, 8 of subsystem offset, then the store's version and byte order
    header = b"MATLAB 5.0 MAT-file".ljust(116, b" ") + bytes(8) + store[:4]
    reader = MatFile5Reader(io.BytesIO(header + store[8:]))
    reader.initialize_read()
    reader.mat_stream.seek(128)
    var, _ = reader.read_var_header()
    arrays: list[np.ndarray] = []
    _collect(reader.read_var_array(var, process=False), arrays)
    whole = [a for a in arrays if np.array_equal(a, np.round(a)) and a.min() >= 1]
    real = [a for a in arrays if not np.array_equal(a, np.round(a))]
    if len(whole) != 1 or len(real) != 1:
        raise ValueError(f"{path}: expected one point array and one connectivity list, found {len(arrays)} n x 3 arrays")
    return real[0].astype(float), whole[0].astype(np.int64) - 1


def _collect(node, found: list) -> None:
    """Every numeric n × 3 array inside nested MATLAB cells and structs."""
    if isinstance(node, np.ndarray) and node.dtype == object:
        for item in node.ravel():
            _collect(item, found)
    elif isinstance(node, np.ndarray) and node.dtype.names:
        for name in node.dtype.names:
            for item in node[name].ravel():
                _collect(item, found)
    elif isinstance(node, np.ndarray) and node.ndim == 2 and node.shape[1] == 3 and node.dtype.kind in "fiu":
        found.append(node)


def main() -> int:
    import pyvista as pv

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mat", type=Path, nargs="+")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for path in args.mat:
        points, triangles = triangulation_arrays(path)
        target = args.out / path.with_suffix(".stl").name
        pv.PolyData.from_regular_faces(points, triangles).save(target)
        print(f"{target}: {len(points)} points, {len(triangles)} triangles, extent {np.ptp(points, axis=0).round(1)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
