"""What a format reader hands back: names, units, metadata and a loader of the used columns."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np


@dataclass(frozen=True)
class Table:
    """One recording as a format holds it, before units and checks.

    ``names`` are the columns (channels, variables) as written; ``units`` their units when the
    format gives them apart from the name (a units row, a ``unit_string`` property), else
    None. ``metadata`` maps key -> value and ``origins`` key -> where it was found ("line 3").
    ``load(indices)`` returns those columns as float arrays; ``where(row)`` names a data row
    in the file's terms ("line 12", "row 7", "sample 7"). ``how_to_add`` tells how to add a
    metadata key to this format, with ``{key}`` for the key.
    """

    names: Sequence[str]
    units: Sequence[str | None]
    metadata: dict[str, Any]
    origins: dict[str, str]
    load: Callable[[list[int]], list[np.ndarray]]
    where: Callable[[int], str]
    how_to_add: str
    word: str = "column"
