"""Variants registered where they are defined: a package of variants imports all its modules.

Load models (:mod:`femstudy.drilling.models`), recording formats
(:mod:`femstudy.recordings.formats`), diagnosis mechanisms (:mod:`femstudy.diagnosis.catalogue`)
and unexplained shapes (:mod:`femstudy.diagnosis.shapes`) are each one module that registers
itself on import; the package's ``__init__`` calls :func:`import_modules` so that importing
the package registers every variant in it.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterable


def import_modules(package: str, path: Iterable[str], skip: Iterable[str] = ()) -> None:
    """Import every module of ``package`` (found on its ``__path__``, ``path``) in name order,
    except those named in ``skip`` (its registry and helpers)."""
    skip = set(skip)
    for name in sorted(m.name for m in pkgutil.iter_modules(path)):
        if name not in skip:
            importlib.import_module(f"{package}.{name}")
