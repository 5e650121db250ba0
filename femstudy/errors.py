"""The exception types of femstudy's failures, and how the command line words each.

A :class:`UserError` is a mistake a user can fix (a file, an option, a value): the command
line prints it as a single ``femstudy: error: ...`` line and exits with status 2. So does a
failure of the machine the user can act on (:func:`environment_message`: no memory, a full
or read-only disk, a missing permission). Anything else is a bug: one line naming a log file
that holds the traceback, and exit status 1 (:mod:`femstudy.cli`).
"""

from __future__ import annotations

import errno


class UserError(Exception):
    """A bad input (file, option, value) explained in one sentence."""


def require(condition: bool, message: str) -> None:
    """Raise :class:`UserError` with ``message`` unless ``condition`` holds."""
    if not condition:
        raise UserError(message)


#: errno values of an OSError the user can act on (disk, permissions, names, limits)
ENVIRONMENT_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.ENOENT,
                      errno.ENOTDIR, errno.EISDIR, errno.EEXIST, errno.ENAMETOOLONG, errno.EMFILE, errno.ENFILE,
                      errno.EFBIG, errno.EIO, errno.ENOTEMPTY, errno.EXDEV, errno.ENOMEM, errno.ELOOP}


def environment_message(exc: BaseException) -> str | None:
    """One sentence for a failure of the machine rather than of femstudy (memory, disk,
    permissions), or None when ``exc`` is not one."""
    if getattr(exc, "environment", False):  # e.g. femstudy.lanes.LaneFailed: a process killed by the machine
        return str(exc)
    if isinstance(exc, MemoryError):
        detail = str(exc).strip()
        return (f"out of memory{f' ({detail})' if detail else ''}: the study is larger than this machine holds; "
                "use a coarser mesh (mesh.size_mm, mesh.site_size_mm), fewer steps or a shorter recording")
    if isinstance(exc, OSError) and exc.errno in ENVIRONMENT_ERRNOS:
        where = exc.filename if exc.filename is not None else ""
        what = exc.strerror or str(exc)
        hint = {errno.ENOSPC: "; free some space or write elsewhere (--out)",
                errno.EDQUOT: "; free some space or write elsewhere (--out)",
                errno.EROFS: "; write elsewhere (--out)"}.get(exc.errno, "")
        return f"{where}: {what}{hint}" if where else f"{what}{hint}"
    return None
