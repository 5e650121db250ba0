"""Answers kept between runs: a study repeated with the same inputs reads its hole models'
verification, its sensitivity table, its thesis step, its resolved run and its assembled model
instead of computing them again.

Each of these is a deterministic function of its inputs (the femur's mesh, surfaces and site,
the global unit fields, the case's loads and options) and of the code that computes it. It is
stored under the SHA-256 of all of them (:func:`digest`), the code counted as the source of
every femstudy module and the versions of Python, numpy, scipy and scikit-fem
(:func:`code_fingerprint`). Only identical inputs under identical code find an answer:
a new load, another option, a remeshed femur or an edited module misses, and the answer is
computed again (its solves then served by the kept solutions of :mod:`femstudy.fe.kept` where
they can be). The files are pickles written atomically in the cache folder, which femstudy
trusts as it trusts its own code; an unreadable one costs a recomputation, never the run.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import logging
import pickle
import platform
import time
from pathlib import Path, PurePath
from typing import Callable, TypeVar

import numpy as np

from femstudy.atomic import atomic_path

log = logging.getLogger(__name__)

T = TypeVar("T")

#: Bumped when the stored form of an answer changes without its code changing.
FORMAT = 1


def _feed(h, obj) -> None:
    """Feed ``obj`` to the hash ``h`` unambiguously: its type, then its content."""
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes, np.generic)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
    elif isinstance(obj, np.ndarray):
        if obj.dtype.hasobject:
            raise TypeError("cannot key an array of Python objects")
        a = np.ascontiguousarray(obj)
        h.update(f"ndarray:{a.dtype.str}:{a.shape};".encode())
        h.update(a.data)
    elif isinstance(obj, (tuple, list)):
        h.update(f"{type(obj).__name__}[{len(obj)}];".encode())
        for item in obj:
            _feed(h, item)
    elif isinstance(obj, dict):
        h.update(f"dict[{len(obj)}];".encode())
        for key in sorted(obj, key=repr):
            _feed(h, key)
            _feed(h, obj[key])
    elif isinstance(obj, (set, frozenset)):
        _feed(h, sorted(obj, key=repr))
    elif isinstance(obj, enum.Enum):
        h.update(f"{type(obj).__qualname__}.{obj.name};".encode())
    elif isinstance(obj, PurePath):
        h.update(f"path:{obj.as_posix()};".encode())
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(f"{type(obj).__module__}.{type(obj).__qualname__};".encode())
        for f in dataclasses.fields(obj):
            _feed(h, f.name)
            _feed(h, getattr(obj, f.name))
    elif hasattr(obj, "model_dump") and hasattr(type(obj), "model_fields"):  # a pydantic model
        h.update(f"{type(obj).__module__}.{type(obj).__qualname__};".encode())
        _feed(h, obj.model_dump())
    else:
        raise TypeError(f"cannot key a {type(obj).__module__}.{type(obj).__qualname__}: only plain values, "
                        "arrays, containers, dataclasses and pydantic models are keyed")


def digest(*parts) -> str:
    """SHA-256 (hex) of ``parts`` and of the code (:func:`code_fingerprint`). Raises TypeError
    for anything whose content it cannot read (a function, an open file), rather than keying
    it by identity."""
    h = hashlib.sha256(f"femstudy kept answer {FORMAT};".encode())
    h.update(code_fingerprint().encode())
    for part in parts:
        _feed(h, part)
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 of every femstudy module's source (by its path in the package) and of the
    versions of Python and of the numerical libraries the answers depend on."""
    import scipy
    import skfem

    package = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for source in sorted(package.rglob("*.py")):
        h.update(source.relative_to(package).as_posix().encode() + b"\0")
        h.update(source.read_bytes() + b"\0")
    h.update(f"python {platform.python_version()} numpy {np.__version__} scipy {scipy.__version__} "
             f"scikit-fem {skfem.__version__}".encode())
    return h.hexdigest()


def kept_answer(folder: Path | None, what: str, parts: tuple, compute: Callable[[], T],
                mark_kept: Callable[[T], T] = lambda answer: answer,
                worth_keeping: Callable[[T], bool] = lambda answer: True, newest: int | None = None) -> T:
    """``compute()``, or the answer kept in ``folder`` under the digest of ``parts`` (then
    passed through ``mark_kept``, so the result can say it was read); a computed answer is
    kept there when ``worth_keeping`` says so, and then only the ``newest`` answers of its kind
    stay (:func:`prune`; all when None). ``folder`` None computes without keeping
    (``--no-kept-solutions``)."""
    if folder is None:
        return compute()
    start = time.perf_counter()
    key = digest(*parts)
    path = Path(folder) / f"{what.replace(' ', '-')}-{key[:32]}.pickle"
    if path.is_file():
        try:
            with open(path, "rb") as stored:
                stored_key, answer = pickle.load(stored)
            if stored_key == key:
                log.info("%s: kept from an earlier run of the same inputs and code (%s), read in %.2f s", what,
                         key[:12], time.perf_counter() - start)
                return mark_kept(answer)
            log.warning("ignoring kept %s %s: its key does not match", what, path)
        except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError, ValueError, TypeError) as exc:
            log.warning("ignoring unreadable kept %s %s (%s)", what, path, exc)
    answer = compute()
    if not worth_keeping(answer):
        return answer
    try:
        with atomic_path(path) as tmp, open(tmp, "wb") as out:
            pickle.dump((key, answer), out, protocol=pickle.HIGHEST_PROTOCOL)
    except (OSError, pickle.PicklingError) as exc:
        log.warning("could not keep the %s in %s (%s)", what, folder, exc)
    if newest is not None:
        prune(Path(folder), what, newest)
    return answer


def prune(folder: Path, what: str, keep: int) -> None:
    """Keep only the newest ``keep`` kept answers of kind ``what`` in ``folder`` (large ones,
    whose every code change keys a new file); another process may be removing the same ones."""
    def modified(path: Path) -> float:
        try:
            return path.stat().st_mtime
        except FileNotFoundError:
            return 0.0

    kept = sorted(Path(folder).glob(f"{what.replace(' ', '-')}-*.pickle"), key=modified)
    for path in kept[:-keep]:
        path.unlink(missing_ok=True)
