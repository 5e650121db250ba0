"""``femstudy diagnose``: what physics a simulation leaves out of a recording."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.commands.metadata import add_metadata_options, parse_settings
from femstudy.commands.options import number
from femstudy.drilling import registry
from femstudy.errors import UserError, require


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("diagnose", help="locate and explain where a recording departs from a simulation",
                       description="Compare a force/torque recording with a simulation: locate where they "
                                   "differ beyond the measurement noise, find which missing mechanisms "
                                   "(chip clogging, feed pulsation, sensor drift, thermal softening) explain "
                                   "it, fit them and show the fit improve, and describe what none of them "
                                   "explains. Reports nothing when nothing is missing. Exit status 0 whatever "
                                   "is found.")
    p.add_argument("recording", type=Path, metavar="RECORDING",
                   help="the recording: CSV/TSV/text export, .tdms, .mat or .xlsx (docs/recordings.md)")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--simulation", type=Path, metavar="SIM.csv",
                      help="a simulated trace in the recording format (any sampling rate, span and "
                           "clock: it is placed on the recording's by correlation)")
    what.add_argument("--model", choices=registry.names("diagnosis"),
                      help="a femstudy load model for the recording's feed, speed and drill, started "
                           "at its detected contact")
    p.add_argument("--bone", default="bovine",
                   help="bone set for --model and for the friction reading of chip clogging (bovine)")
    p.add_argument("--cortex-mm", type=number(0, 20, "mm"),
                   help="cortical thickness [mm] (default: header cortex_mm, else the simulation's "
                        "breakthrough, else the depth reached, with a note)")
    add_metadata_options(p, "the recording")
    p.add_argument("--json", type=Path, metavar="OUT.json", help="write the diagnosis as JSON")
    p.add_argument("--report", type=Path, metavar="DIR",
                   help="write report.md, overlay.png, residuals.png and diagnosis.json to DIR")
    p.add_argument("--plot", type=Path, metavar="OUT.png", help="write the overlay and residual figure")
    p.add_argument("--workers", type=number(1, 256, integer=True, low_open=False),
                   help="processes the fits are spread over (default: one per core; 1: all in this one)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.diagnosis import diagnose

    from femstudy.recordings.formats.size import MAX_ANALYSED_SAMPLES, check_recording_size
    from femstudy.writable import check_output_file, check_output_folder

    require(args.plot is None or args.plot.suffix.lower() in (".png", ".pdf", ".svg"),
            f"--plot must end in .png, .pdf or .svg, got '{args.plot}'")
    require(args.json is None or args.json.suffix.lower() == ".json", f"--json must end in .json, got '{args.json}'")
    inputs = [args.recording, *([args.simulation] if args.simulation else [])]
    for path, what in ((args.json, "the diagnosis"), (args.plot, "the figure")):
        if path is not None:
            check_output_file(path, what, inputs=inputs)
    if args.report is not None:
        check_output_folder(args.report, "the diagnosis report", inputs=inputs, cache_dir=args.settings.cache_dir)
    for path in inputs:
        check_recording_size(path, MAX_ANALYSED_SAMPLES, "diagnose")
    d = diagnose(args.recording, args.simulation, args.cortex_mm, args.bone, model=args.model,
                 columns=args.columns, overrides=parse_settings(args.set), override_header=args.override,
                 bone_library=args.settings.bones_dir, workers=args.workers)
    _require_finite(d.to_json(), args.recording.name)
    print(d.summary())
    for path in d.write(args.json, args.plot, args.report):
        print(f"wrote {path}")
    return 0


#: An R² below this is no fit but a channel without variation (a residual a million times
#: its variance).
LOWEST_R2 = -1e6


def _require_finite(doc: dict, name: str) -> None:
    """Refuse a diagnosis holding a number that is not finite, or an R² below
    :data:`LOWEST_R2` (a channel without variation makes both): it would be printed and
    written as if it meant something."""
    import math

    from femstudy.study.plausibility import numbers_in

    for path, value in numbers_in(doc):
        if not math.isfinite(value) or (path[-1].startswith("r2") and value < LOWEST_R2):
            where = ".".join(p for p in path)
            raise UserError(f"the diagnosis of {name} came to {where} = {value}, which is no result: a channel of "
                            "the recording or the simulation hardly varies; check them")
