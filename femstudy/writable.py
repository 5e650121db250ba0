"""Check output locations before any work: writable, and never something of the user's.

A folder femstudy writes whole (results, mesh outputs, calibration tables, diagnosis reports,
data sets) replaces what is at its place, so that place must be empty, absent, or a folder
femstudy wrote and nothing else touched: its marker (:data:`femstudy.marker.MARKER`) lists
every file in it. Never the working folder or one of its parents (``.``, ``..``), the mesh
cache or anything in it, nor a folder holding the inputs. A file output must not be a folder
or one of the inputs. Each refusal is one :class:`~femstudy.errors.UserError` sentence.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterable

from femstudy.errors import UserError


def _resolved(path: Path) -> Path:
    return Path(os.path.abspath(Path(path).expanduser())).resolve()


def _not_the_working_folder(target: Path, where: str) -> None:
    resolved, cwd = _resolved(target), _resolved(Path.cwd())
    if resolved == cwd or resolved in cwd.parents:
        raise UserError(f"{where}: it is the working folder{' or holds it' if resolved != cwd else ''}, which "
                        "femstudy would replace as a whole; name a new folder")


def check_replaceable_folder(target: str | os.PathLike, what: str = "results") -> None:
    """Raise :class:`UserError` unless a folder femstudy builds may take the place of
    ``target``: absent, empty, or written by femstudy (its marker lists everything in it)."""
    from femstudy.marker import MARKER, written_files

    target = Path(target)
    where = f"cannot write {what} to {target}"
    _not_the_working_folder(target, where)
    if target.is_symlink():
        raise UserError(f"{where}: it is a symbolic link; name a folder")
    if not target.exists():
        return
    if not target.is_dir():
        raise UserError(f"{where}: it exists and is a file, not a folder")
    try:
        present = written_files(target)
        marker = target / MARKER
        if not present and not marker.exists():
            return
        if not marker.is_file():
            raise UserError(f"{where}: the folder exists and femstudy did not write it (it has no {MARKER}); "
                            "femstudy replaces only folders it wrote: name a new folder, or empty this one yourself")
        listed = json.loads(marker.read_text(encoding="utf-8")).get("files", [])
    except OSError as exc:
        raise UserError(f"{where}: {exc.strerror or exc}") from None
    except (json.JSONDecodeError, AttributeError, UnicodeDecodeError):
        raise UserError(f"{where}: its {MARKER} is damaged, so femstudy cannot tell what it wrote there; "
                        "name a new folder") from None
    added = [name for name in present if name not in set(listed)]
    if added:
        raise UserError(f"{where}: it holds {added[0]}{f' and {len(added) - 1} more' if len(added) > 1 else ''}, "
                        "which femstudy did not write and would delete; move it away or name a new folder")


def check_output_folder(target: str | os.PathLike, what: str = "results", *, inputs: Iterable = (),
                        cache_dir: str | os.PathLike | None = None) -> None:
    """Raise :class:`UserError`, before any work, unless femstudy may write the folder
    ``target``: replaceable (:func:`check_replaceable_folder`), not holding one of ``inputs``
    (files or folders read), neither the cache folder, inside it (unless the working folder
    is), nor holding it, and in a writable place."""
    target = Path(target)
    where = f"cannot write {what} to {target}"
    _not_the_working_folder(target, where)
    resolved = _resolved(target)
    for item in inputs:
        item = _resolved(Path(item))
        if resolved == item or resolved in item.parents:
            raise UserError(f"{where}: it {'is' if resolved == item else 'holds'} the input {item}, which femstudy "
                            "would replace; name a new folder")
    if cache_dir is not None:
        cache = _resolved(Path(cache_dir))
        cwd = _resolved(Path.cwd())
        inside = cache in resolved.parents and not (cache == cwd or cache in cwd.parents)
        if resolved == cache or resolved in cache.parents or inside:  # inside: unless one works in the cache
            relation = ("the mesh cache" if resolved == cache else
                        "inside the mesh cache" if cache in resolved.parents else "a folder holding the mesh cache")
            raise UserError(f"{where}: it is {relation} ({cache_dir}); name a folder outside it")
    check_replaceable_folder(target, what)
    require_writable_parent(target, what)


def claim_folder(target: str | os.PathLike, what: str, *, inputs: Iterable = (),
                 cache_dir: str | os.PathLike | None = None) -> Path:
    """Make ``target`` a folder femstudy adds files to over several runs (a sweep, which
    resumes): absent or empty (then marked as femstudy's), or already marked; anything else is
    refused as by :func:`check_output_folder`. Returns the folder."""
    from femstudy.marker import MARKER

    target = Path(target)
    if (target / MARKER).is_file():
        return target
    check_output_folder(target, what, inputs=inputs, cache_dir=cache_dir)
    if target.exists() and any(target.iterdir()):
        raise UserError(f"cannot write {what} to {target}: the folder exists and femstudy did not write it (it has no "
                        f"{MARKER}); name a new folder")
    target.mkdir(parents=True, exist_ok=True)
    (target / MARKER).write_text(json.dumps({"written_by": "femstudy", "complete": False, "files": []}) + "\n",
                                 encoding="utf-8")
    return target


def check_output_file(target: str | os.PathLike, what: str, *, inputs: Iterable = ()) -> None:
    """Raise :class:`UserError`, before any work, unless the file ``target`` can be written:
    not a folder, not one of ``inputs``, in a writable place."""
    target = Path(target)
    where = f"cannot write {what} to {target}"
    if target.is_dir():
        raise UserError(f"{where}: it is a folder; name a file")
    if target.exists() and not target.is_file():
        raise UserError(f"{where}: it exists and is not a regular file")
    resolved = _resolved(target)
    for item in inputs:
        if resolved == _resolved(Path(item)):
            raise UserError(f"{where}: it is an input of this command, which femstudy would overwrite")
    require_writable_parent(target, what, folder=False)


def require_writable_parent(target: str | os.PathLike, what: str = "results", folder: bool = True) -> None:
    """Raise :class:`UserError` unless ``target`` (a folder, or a file if not ``folder``) can be
    created or replaced."""
    target = Path(target)
    parent = target.parent
    existing = parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise UserError(f"cannot write {what} to {target}: {existing} is not a folder")
    if folder and target.exists() and not target.is_dir():
        raise UserError(f"cannot write {what} to {target}: it exists and is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(f"cannot write {what} to {target}: {existing} is not writable")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise UserError(f"cannot write {what} to {target}: {exc.strerror or exc}") from None


def require_free_space(target: str | os.PathLike, need_bytes: float, what: str = "results") -> None:
    """Raise :class:`UserError` unless the disk that will hold ``target`` has ``need_bytes``
    free (checked before the work, so that a full disk does not fail it half-way)."""
    existing = Path(target)
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    try:
        free = shutil.disk_usage(existing).free
    except OSError:
        return
    if free < need_bytes:
        raise UserError(f"cannot write {what} to {target}: {free / 1e6:.0f} MB free on its disk, and they need about "
                        f"{need_bytes / 1e6:.0f} MB; free some space or write elsewhere")
