"""A recording's metadata (feed, speed, drill ...): one schema, messages that name key and place.

Every format carries ``key = value`` metadata in its own place (a ``# key = value`` line, a
TDMS property, a MATLAB variable, a spreadsheet row); the format reader records where each
key was found, so that a bad value is reported as e.g. ``recording rec.csv, line 3:
feed_mm_s: Input should be greater than 0, got -1.5``. Values given on the command line
(``--set``) must agree with the file unless ``override_header`` is set.
"""

from __future__ import annotations

import difflib
import json
import math
import tomllib
from typing import Any, Mapping

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from femstudy.errors import UserError

COMMAND_LINE = "the command line (--set)"


class RecordingMetadata(BaseModel):
    """Metadata keys femstudy interprets; any other key is kept as given.

    Units are in the names: feed [mm/s], spindle speed [rpm], drill diameter [mm], point
    angle [degrees], ``contact_s``/``cut_end_s`` [s] override the automatic isolation of the cut.
    """

    model_config = ConfigDict(extra="allow", frozen=True, coerce_numbers_to_str=True)

    feed_mm_s: float = Field(gt=0, le=50, allow_inf_nan=False)
    spindle_rpm: float = Field(gt=0, le=100_000, allow_inf_nan=False)
    drill_diameter_mm: float = Field(2.7, gt=0, le=20, allow_inf_nan=False)
    point_angle_deg: float = Field(90.0, gt=0, lt=180)
    specimen: str = ""
    samples: int | None = Field(None, ge=0)
    contact_s: float | None = Field(None, allow_inf_nan=False)
    cut_end_s: float | None = Field(None, allow_inf_nan=False)

    @field_validator("feed_mm_s", "spindle_rpm", "drill_diameter_mm", "point_angle_deg", "samples", "contact_s",
                     "cut_end_s", mode="before")
    @classmethod
    def _not_a_truth_value(cls, value):
        if isinstance(value, (bool, np.bool_)):
            raise ValueError("Input should be a number, not true or false")
        return value


REQUIRED_KEYS = tuple(k for k, f in RecordingMetadata.model_fields.items() if f.is_required())


def parse_text_value(text: str, decimal: str = ".") -> Any:
    """A metadata value written as text: TOML (``1.5``, ``"femur 3"``, ``[1, 2]``, ``true``),
    a decimal-comma number (``1,5`` when ``decimal`` is ","), else the text itself."""
    text = text.strip()
    if decimal == "," and text.count(",") == 1 and text.replace(",", "", 1).lstrip("+-").isdigit():
        text = text.replace(",", ".")
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def plain_value(value: Any) -> Any:
    """A value read from a binary format as a plain Python value: numpy scalars and
    one-element arrays unwrapped, TOML arrays written as text (``"[...]"``) parsed back."""
    if isinstance(value, np.ndarray):
        value = value.item() if value.size == 1 else value.tolist()
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if isinstance(value, str) and value.strip().startswith("["):
        parsed = parse_text_value(value)
        return parsed if isinstance(parsed, list) else value
    return value


def format_header_value(value) -> str:
    """A Python value as a TOML value for a ``# key = value`` line."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if math.isfinite(value) else ("nan" if math.isnan(value) else
                                                                ("inf" if value > 0 else "-inf"))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_header_value(v) for v in value) + "]"
    return json.dumps(str(value))


def validate_metadata(found: Mapping[str, Any], origins: Mapping[str, str], overrides: Mapping[str, Any],
                      override_header: bool, source: str, how_to_add: str) -> tuple[dict, list[str]]:
    """The file's metadata combined with the command line's, checked against the schema.

    Parameters
    ----------
    found : mapping
        Key -> value as read from the file.
    origins : mapping
        Key -> where the file holds it (``"line 3"``, ``"file property feed_mm_s"``).
    overrides : mapping
        Key -> value from the command line (``--set``).
    override_header : bool
        Let the command line win when it disagrees with the file (with a note); else refuse.
    source : str
        The file's name, for messages.
    how_to_add : str
        How to add a key to this format, e.g. ``"add '# {key} = ...' to its header"``.

    Returns
    -------
    (dict, list of str)
        Every key with its checked value (defaults filled in), and notes on overrides.

    Examples
    --------
    >>> meta, notes = validate_metadata({"feed_mm_s": 1.5, "spindle_rpm": 1500}, {}, {}, False, "r.csv", "")
    >>> meta["drill_diameter_mm"]
    2.7
    """
    values, where = dict(found), dict(origins)
    notes = []
    for key, value in overrides.items():
        if key in values and not _same(values[key], value):
            if not override_header:
                raise UserError(f"recording {source}: its header says {key} = {show(values[key])} but the "
                                f"command line says {show(value)}; remove one of them, or pass "
                                f"--override to let the command line win")
            notes.append(f"{key} = {show(value)} from the command line overrides "
                         f"{show(values[key])} in the header")
        values[key], where[key] = value, COMMAND_LINE
    for key in REQUIRED_KEYS:
        if key not in values:
            near = difflib.get_close_matches(key, list(values), n=1, cutoff=0.75)
            hint = f" ({where.get(near[0], 'the file')} has {near[0]}: a misspelling?)" if near else ""
            raise UserError(f"recording {source} has no {key}{hint}: {how_to_add.format(key=key)} or give it "
                            f"on the command line (--set {key}=...)")
    try:
        model = RecordingMetadata(**values)
    except ValidationError as exc:
        error = exc.errors()[0]
        key = str(error["loc"][0]) if error["loc"] else "(metadata)"
        place = f", {where[key]}" if key in where else ""
        raise UserError(f"recording {source}{place}: {key}: {error['msg'].removeprefix('Value error, ')}, "
                        f"got {show(values.get(key))}") from None
    return {**values, **model.model_dump(exclude_none=True)}, notes


def _same(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return a == b


def show(value) -> str:
    """A value as it is written in a header: text quoted, numbers as they are."""
    return json.dumps(value) if isinstance(value, str) else repr(value)


def check_declared_samples(metadata: Mapping[str, Any], limit: int, source: str) -> None:
    """Refuse a header that claims more samples than femstudy reads, before reading them."""
    declared = metadata.get("samples")
    if declared and declared > limit:
        raise UserError(f"recording {source}: the header claims {declared:,} samples; femstudy reads at most "
                        f"{limit:,}: split the recording")
