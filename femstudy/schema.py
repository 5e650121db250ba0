"""TOML files checked against pydantic schemas, with errors that name the key and the line.

Every file femstudy reads that has a structure (case files, sweep files, bone sets) goes
through :func:`parse_toml`: one ``path:line: key: what was expected, got …`` sentence for the
first problem, and how many more there are. Validation is strict: a TOML value must already
have the key's type (``true`` is not a number, ``"2.0"`` is not a number, ``2.0`` is not a
count); an integer is taken where a real number is expected.
"""

from __future__ import annotations

import difflib
import re
import tomllib
from typing import Callable, TypeVar, get_args, get_origin

from pydantic import BaseModel, ValidationError

from femstudy.errors import UserError

Model = TypeVar("Model", bound=BaseModel)


def _dotted(key: str) -> list[str]:
    """The parts of a TOML dotted key, quoted parts kept whole: 'a."b.c"' → [a, b.c]."""
    return [part.strip().strip('"') for part in re.findall(r'"[^"]*"|[^.]+', key)]


def key_line(text: str, keys: list[str]) -> int | None:
    """Best-effort 1-based line of the TOML key path ``keys`` (array-of-tables entries numbered
    from 0), else of its nearest table."""
    table: list[str] = []
    arrays: dict[tuple, int] = {}  # [[x]] tables seen so far: the next one's index
    best, best_depth = None, 0
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        header = re.fullmatch(r"(\[\[?)\s*([^\]]+?)\s*\]\]?", line)
        if header:
            table = _dotted(header.group(2))
            if header.group(1) == "[[":  # an array of tables: its entries are numbered
                index = arrays.get(tuple(table), 0)
                arrays[tuple(table)] = index + 1
                table = table + [str(index)]
            if table == keys[: len(table)] and len(table) > best_depth:
                best, best_depth = number, len(table)
            continue
        match = re.match(r'((?:"[^"]*"|[A-Za-z0-9_-]+)(?:\s*\.\s*(?:"[^"]*"|[A-Za-z0-9_-]+))*)\s*=', line)
        if match:
            path = table + _dotted(match.group(1))
            if path == keys[: len(path)] and len(path) > best_depth:
                best, best_depth = number, len(path)
    return best


def _model(annotation) -> type[BaseModel] | None:
    return annotation if isinstance(annotation, type) and issubclass(annotation, BaseModel) else None


def field_path(loc: tuple, model: type[BaseModel]) -> tuple[list[str], type[BaseModel] | None]:
    """The TOML key path of an error location, without pydantic's union-member tags,
    and the model owning the last key. Inside a list or a table of free keys the index or
    key is kept, and the items' model followed."""
    keys: list[str] = []
    owner: type[BaseModel] | None = model
    items = None  # the element annotation of a list or dict field just entered
    for item in loc:
        if items is not None:
            keys.append(str(item))
            owner, items = _model(items), None
        elif owner is not None and isinstance(item, str) and item in owner.model_fields:
            keys.append(item)
            annotation = owner.model_fields[item].annotation
            origin, args = get_origin(annotation), get_args(annotation)
            if origin in (list, dict) and args:
                owner, items = None, args[-1]
            else:
                owner = _model(annotation)
        elif isinstance(item, int) and owner is not None:
            keys.append(str(item))
        elif owner is not None and isinstance(item, str):  # an unknown key
            keys.append(item)
            return keys, owner
    return keys, owner


def describe(errors: list[dict], model: type[BaseModel]) -> tuple[list[str], str]:
    """The key path and a one-line message for the first problem (union members merged)."""
    keys, owner = field_path(errors[0]["loc"], model)
    same = [e for e in errors if field_path(e["loc"], model)[0] == keys]
    dotted = ".".join(keys) or "(file)"
    if errors[0]["type"] == "extra_forbidden":
        valid = [v for v in (owner.model_fields if owner else []) if v != "source"]
        near = difflib.get_close_matches(keys[-1], valid, n=1)
        hint = f"did you mean '{near[0]}'?" if near else f"valid keys: {', '.join(valid)}"
        return keys, f"{dotted}: unknown key; {hint}"
    messages = list(dict.fromkeys(e["msg"].replace("Value error, ", "") for e in same))
    expected = ", or ".join([messages[0]] + [m.removeprefix("Input should be ") for m in messages[1:]])
    got = errors[0].get("input")
    shown = "" if isinstance(got, dict) or errors[0]["type"] == "missing" else f", got {got!r}"
    return keys, f"{dotted}: {expected}{shown}"


def parse_toml(text: str, model: type[Model], where: str, prepare: Callable[[dict], dict] | None = None) -> Model:
    """Validate TOML ``text`` against ``model``; ``where`` names the file in messages and
    ``prepare`` may fill defaults into the parsed document first."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{where}: TOML syntax error: {exc}") from None
    if prepare is not None:
        data = prepare(data)
    try:
        return model.model_validate(data, strict=True)
    except ValidationError as exc:
        errors = exc.errors()
        keys, message = describe(errors, model)
        line = key_line(text, keys)
        others = {tuple(field_path(e["loc"], model)[0]) for e in errors} - {tuple(keys)}
        more = f" (and {len(others)} more problem{'s' if len(others) > 1 else ''})" if others else ""
        raise UserError(f"{where}{f':{line}' if line else ''}: {message}{more}") from None
