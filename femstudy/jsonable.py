"""Plain JSON values from results that hold numpy scalars, arrays and paths."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def default(value):
    """``json.dumps(..., default=default)``: numpy scalars and arrays, paths."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def jsonable(value):
    """``value`` with every numpy or path object replaced by its plain JSON equivalent."""
    return json.loads(json.dumps(value, default=default))
