"""On-disk cache of built meshes, keyed by everything that changes them.

The key is the SHA-256 of a canonical JSON document holding the input surface's SHA-256,
every parameter that changes the mesh, the femstudy and pytetwild versions and
:data:`LAYOUT` (bumped when the meshing pipeline changes its output). An entry is a folder ``<root>/<key>/``
with ``mesh.npz`` (arrays) and ``meta.json`` (metadata and the SHA-256 of ``mesh.npz``),
written under a temporary name and renamed into place when complete, so an interrupted
build leaves no entry that looks complete. Loading verifies the checksum; a corrupted entry
is reported in one line, removed and rebuilt by the caller.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import shutil
from pathlib import Path

import numpy as np

from femstudy import __version__, atomic

log = logging.getLogger(__name__)

LAYOUT = 2
#: The cache folder when none is given (the command line reads ``$FEMSTUDY_CACHE``).
DEFAULT_CACHE_DIR = Path(".femstudy-cache")


def cache_key(parts: dict) -> str:
    """SHA-256 of the canonical JSON of ``parts`` plus the femstudy and pytetwild versions and
    the layout (fTetWild is not deterministic, so another version would give another mesh)."""
    from importlib.metadata import version

    doc = json.dumps({"femstudy": __version__, "pytetwild": version("pytetwild"), "layout": LAYOUT, **parts},
                     sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(doc.encode()).hexdigest()


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def load(key: str, root: Path = DEFAULT_CACHE_DIR) -> tuple[dict, dict] | None:
    """(arrays, meta) of a verified entry, or None if absent or corrupted (then removed)."""
    folder = Path(root) / key
    if not folder.is_dir():
        return None
    try:
        meta = json.loads((folder / "meta.json").read_text(encoding="utf-8"))
        data = (folder / "mesh.npz").read_bytes()
        if _sha256(data) != meta["mesh_sha256"]:
            raise ValueError("checksum mismatch")
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, KeyError, json.JSONDecodeError) as exc:
        log.warning("mesh cache entry %s in %s is corrupted (%s); rebuilding it", key[:12], folder.parent, exc)
        shutil.rmtree(folder, ignore_errors=True)
        return None
    return arrays, meta


def store(key: str, arrays: dict, meta: dict, root: Path = DEFAULT_CACHE_DIR) -> Path:
    """Write an entry atomically; returns its folder."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    data = buf.getvalue()
    folder = Path(root) / key
    with atomic.atomic_folder(folder) as tmp:
        (tmp / "mesh.npz").write_bytes(data)
        (tmp / "meta.json").write_text(json.dumps({**meta, "mesh_sha256": _sha256(data)}, indent=1,
                                                  default=str), encoding="utf-8")
    return folder
