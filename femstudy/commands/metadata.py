"""The ``--set KEY=VALUE`` / ``--override`` / ``--columns`` options that say how to read recordings."""

from __future__ import annotations

import argparse
import re
import tomllib

from femstudy.errors import require


def add_metadata_options(parser: argparse.ArgumentParser, whose: str) -> None:
    """Add ``--set`` and ``--override``; ``whose`` names the recordings ("every recording")."""
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help=f"metadata for {whose}, e.g. --set spindle_rpm=1500 (TOML value)")
    parser.add_argument("--override", action="store_true",
                        help=f"let --set values win over {whose}'s header when they disagree")
    parser.add_argument("--columns", metavar="QUANTITY=COLUMN,...",
                        help=f"which column of {whose} is which quantity, with its unit in brackets when the "
                             f"file has none, e.g. time=Zeit[ms],thrust=Fz,torque=Mz[N*m] (quantities: time, "
                             f"thrust, torque, depth, fx, fy)")


def parse_settings(items: list[str]) -> dict:
    """``KEY=VALUE`` pairs; VALUE is read as TOML (1.5, "text", true), else kept as text."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        require(sep and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", key),
                f"--set expects KEY=VALUE with a metadata key such as feed_mm_s, got '{item}'")
        try:
            out[key] = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = value.strip()
    return out
