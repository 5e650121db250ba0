"""``femstudy view``: look at a results folder in PyVista."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from femstudy.commands.options import number

FIELDS = {"von_mises": "von_mises_MPa", "displacement": "displacement_magnitude_mm", "region": "region"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="view a results folder (interactive, or an off-screen screenshot)",
                       description="Show the deformed femur of a 'femstudy run' results folder. With a "
                                   "display: an interactive window with a time slider. Without one, or "
                                   "with --screenshot: an off-screen PNG.")
    p.add_argument("results", type=Path, help="results folder written by 'femstudy run'")
    p.add_argument("--loading", choices=("dynamic", "static"), default="dynamic")
    p.add_argument("--time", type=number(-1e6, 1e6, "s"), default=None, metavar="T",
                   help="time [s] to show (default: the time of peak deflection)")
    p.add_argument("--field", choices=tuple(FIELDS), default="von_mises")
    p.add_argument("--warp", type=number(0, 1e12), default=None, metavar="F",
                   help="deformation scale factor (default: the one in summary.json)")
    p.add_argument("--screenshot", type=Path, default=None, metavar="PNG",
                   help="write a PNG instead of opening a window")
    p.set_defaults(run=run)


def has_display() -> bool:
    """True when an interactive window can be opened."""
    return sys.platform in ("win32", "darwin") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def run(args: argparse.Namespace) -> int:
    from femstudy.study.viewer import view
    from femstudy.writable import check_output_file

    if args.screenshot is not None:
        check_output_file(args.screenshot, "the screenshot")
    written = view(args.results, loading=args.loading, time_s=args.time, field=FIELDS[args.field],
                   warp=args.warp, screenshot=args.screenshot, interactive=has_display())
    if written is not None:
        print(f"wrote {written}")
    return 0
