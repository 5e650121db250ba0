"""Atomic file and folder writes: a reader never sees half a result, and femstudy replaces
only what it wrote.

Files are written to a temporary sibling and renamed over the target (``os.replace`` is
atomic on POSIX within one file system); folders are built under a temporary sibling name
and renamed into place when complete.

Every folder written whole carries a marker, :data:`MARKER`, listing the files femstudy put
in it. An existing folder is replaced only when its marker says femstudy wrote it and it
holds nothing else (:func:`femstudy.writable.check_replaceable_folder`): a folder of the
user's, one with a file the user added, the working folder or one of its parents is refused
in one line, never deleted. The temporary names carry the writing process's id; one left by
a process that no longer runs (killed) is removed by the next write into the same folder.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from femstudy.marker import MARKER, written_files

#: Temporary sibling folders: ``.<name>.partial-<pid>-<random>`` (a folder being built) and
#: ``.<name>.old-<pid>`` (the folder it replaces, while swapping).
_LEFTOVER = re.compile(r"^\..*\.(?:partial-(\d+)-[^/]*|old-(\d+))$")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _alive(pid: int) -> bool:
    """Whether a process with this id runs (a stranger reusing the id counts as alive: then
    the leftover is kept, which is the safe side)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_leftovers(parent: Path) -> list[Path]:
    """Remove the temporary folders that folder writes into ``parent`` left behind when their
    process was killed (their names say which process, and they hold the marker, so nothing
    but femstudy's own leftovers is touched); returns what was removed."""
    removed = []
    try:
        entries = list(Path(parent).iterdir())
    except OSError:
        return removed
    for entry in entries:
        match = _LEFTOVER.match(entry.name)
        if not match or _alive(int(next(g for g in match.groups() if g))):
            continue
        if entry.is_dir() and not entry.is_symlink() and (entry / MARKER).is_file():
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``target``; move it onto ``target`` on success."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes it private; a result is an ordinary file
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def write_text(target: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``target`` atomically (UTF-8)."""
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _mark(folder: Path, files: list[str] | None) -> None:
    from femstudy import __version__

    text = json.dumps({"written_by": "femstudy", "femstudy_version": __version__, "complete": files is not None,
                       "files": files or []}, indent=1)
    (folder / MARKER).write_text(text + "\n", encoding="utf-8")


@contextlib.contextmanager
def atomic_folder(target: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty temporary folder; on success it replaces ``target`` as a whole.

    ``target`` must be absent, or a folder femstudy wrote and nothing else touched
    (:func:`femstudy.writable.check_replaceable_folder`; anything else is a
    :class:`~femstudy.errors.UserError` and nothing is written). An existing ``target`` is
    swapped out only after the new folder is complete, so an interrupted run leaves the
    previous result (or nothing) in place, plus at most a hidden ``.<name>.partial-<pid>-*``
    folder that is never mistaken for a result and that the next write removes.
    """
    from femstudy.writable import check_replaceable_folder

    target = Path(target)
    check_replaceable_folder(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_leftovers(target.parent)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.partial-{os.getpid()}-", dir=target.parent))
    tmp.chmod(0o777 & ~_umask())
    try:
        _mark(tmp, None)
        yield tmp
        _mark(tmp, written_files(tmp))
        check_replaceable_folder(target)  # again: something may have appeared there meanwhile
        try:
            os.replace(tmp, target)
        except OSError:  # target exists (or appeared meanwhile: another process stored it) and is not empty
            old = target.with_name(f".{target.name}.old-{os.getpid()}")
            os.replace(target, old)
            os.replace(tmp, target)
            shutil.rmtree(old, ignore_errors=True)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
