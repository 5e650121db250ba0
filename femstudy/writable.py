"""Check early that an output location can be written, before long work starts."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from femstudy.errors import UserError


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
    try:
        parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise UserError(f"cannot write {what} to {target}: {exc.strerror or exc}") from None
