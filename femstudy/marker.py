"""The marker of a folder femstudy wrote whole, and the files such a folder holds.

:mod:`femstudy.atomic` writes the marker; :mod:`femstudy.writable` reads it before a folder
may be replaced. Both take these two names from here.
"""

from __future__ import annotations

from pathlib import Path

#: The marker file of a folder femstudy wrote whole: JSON with the files it holds.
MARKER = ".femstudy.json"


def written_files(folder: Path) -> list[str]:
    """Every file and folder under ``folder`` (relative POSIX paths), the marker excepted."""
    return sorted(p.relative_to(folder).as_posix() for p in Path(folder).rglob("*") if p.name != MARKER)
