"""``femstudy calibrate``: friction coefficients and a bone set from force/torque recordings."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.commands.metadata import add_metadata_options, parse_settings
from femstudy.commands.options import number


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate the chip-evacuation model on recordings",
                       description="Isolate, de-drift and filter each recording, fit mu_f and mu_w per run "
                                   "and per condition (Eq 4.4), flag outliers, fit the power law (Eqs 4.5-4.7), "
                                   "validate on held-out runs, test F_o and p for normality and run the "
                                   "neural-network neuron study; save the result as a named bone set that "
                                   "'femstudy loads --bone NAME' and case files ([drilling] bone = \"NAME\") use.")
    p.add_argument("runs", nargs="+", type=Path, metavar="RUNS",
                   help="recordings (CSV, text exports, .tdms, .mat, .xlsx) or folders of recordings, at four "
                        "or more (feed, speed) conditions")
    p.add_argument("--name", default="calibrated", help="name of the bone set to save (calibrated)")
    p.add_argument("--out", type=Path, help="folder for tables and figures (results/calibration/NAME); "
                                            "replaced as a whole")
    p.add_argument("--validate", nargs="+", type=Path, default=[], metavar="RUNS",
                   help="held-out recordings (e.g. at other conditions); default: --holdout replicates")
    p.add_argument("--holdout", type=number(0, 1000, integer=True, low_open=False), default=2,
                   help="replicates held out per condition when no --validate is given (2)")
    add_metadata_options(p, "every recording")
    p.add_argument("--cutoff-hz", type=number(0, 5000, "Hz"), help="low-pass cut-off [Hz] (default from the feed, Table 4-4)")
    p.add_argument("--no-ann", action="store_true", help="skip the neural-network neuron study")
    p.add_argument("--no-figures", action="store_true", help="write tables only")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.recordings.workflow import calibrate

    result = calibrate(args.runs, args.validate, name=args.name, out=args.out, holdout=args.holdout,
                       metadata=parse_settings(args.set), override=args.override, columns=args.columns,
                       cutoff_hz=args.cutoff_hz,
                       neurons=not args.no_ann, figures=not args.no_figures, bones_dir=args.settings.bones_dir)
    print(result.files["report"])
    print(f"wrote {result.files['folder']}")
    return 0
