"""On-disk cache of built meshes, keyed by everything that changes them.

The key is the SHA-256 of a canonical JSON document holding the input surface's SHA-256,
every parameter that changes the mesh, the femstudy and pytetwild versions and
:data:`LAYOUT` (bumped when the meshing pipeline changes its output). An entry is a folder ``<root>/<key>/``
with ``mesh.npz`` (arrays) and ``meta.json`` (metadata: the frame, the mesh's quality and
statistics), written under a temporary name and renamed into place when complete, so an
interrupted build leaves no entry that looks complete.

Everything an entry's result depends on is checksummed: ``meta.json`` records the SHA-256 of
``mesh.npz`` and of its own metadata (in canonical JSON), and loading verifies both, so a
damaged or edited entry (an anterior axis negated in its frame, say) is reported in one line,
removed and rebuilt by the caller. Nothing in it is unpickled (``allow_pickle=False``).

While an entry is built its key is locked (:func:`lock`: an advisory ``flock`` on
``<root>/.locks/<key>.lock``, released by the kernel if the process dies): a second process
asking for the same mesh waits and then loads the first one's entry, instead of running
TetWild again and storing another mesh under the same key (TetWild is not deterministic).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import io
import json
import logging
import shutil
from pathlib import Path
from typing import Iterator

import numpy as np

from femstudy import __version__, atomic

log = logging.getLogger(__name__)

LAYOUT = 3
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


def _canonical(meta: dict) -> bytes:
    """The metadata as the checksum sees it: JSON with sorted keys, as it reads back."""
    return json.dumps(meta, sort_keys=True, separators=(",", ":"), default=str).encode()


@contextlib.contextmanager
def lock(key: str, root: Path = DEFAULT_CACHE_DIR) -> Iterator[None]:
    """Hold the build lock of entry ``key`` (see the module docstring); waits for a process
    that holds it, saying so."""
    folder = Path(root) / ".locks"
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / f"{key}.lock", "a+b") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            log.info("waiting for another femstudy process that is building mesh %s (%s)", key[:12], root)
            fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def load(key: str, root: Path = DEFAULT_CACHE_DIR) -> tuple[dict, dict] | None:
    """(arrays, meta) of a verified entry, or None if absent or corrupted (then removed)."""
    folder = Path(root) / key
    if not folder.is_dir():
        return None
    try:
        record = json.loads((folder / "meta.json").read_text(encoding="utf-8"))
        meta = record["meta"]
        if _sha256(_canonical(meta)) != record["meta_sha256"]:
            raise ValueError("meta.json does not match its checksum")
        data = (folder / "mesh.npz").read_bytes()
        if _sha256(data) != record["mesh_sha256"]:
            raise ValueError("mesh.npz does not match its checksum")
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, KeyError, TypeError, json.JSONDecodeError) as exc:
        log.warning("mesh cache entry %s in %s is corrupted (%s); rebuilding it", key[:12], folder.parent, exc)
        shutil.rmtree(folder, ignore_errors=True)
        return None
    return arrays, meta


def store(key: str, arrays: dict, meta: dict, root: Path = DEFAULT_CACHE_DIR) -> tuple[dict, dict]:
    """Write an entry atomically and return (arrays, meta) as the cache now holds them: these,
    or those of a sound entry another process stored first under the same key (the first
    writer wins, so every run that names the key describes the same mesh)."""
    existing = load(key, root)
    if existing is not None:
        log.info("mesh %s was stored meanwhile by another process; using that one", key[:12])
        return existing
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    data = buf.getvalue()
    meta = json.loads(_canonical(meta))  # as it will read back (tuples as lists, paths as text)
    with atomic.atomic_folder(Path(root) / key) as tmp:
        (tmp / "mesh.npz").write_bytes(data)
        (tmp / "meta.json").write_text(json.dumps({"meta": meta, "mesh_sha256": _sha256(data),
                                                   "meta_sha256": _sha256(_canonical(meta))}, indent=1),
                                       encoding="utf-8")
    return arrays, meta
