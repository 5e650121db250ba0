"""``femstudy calibrate``: friction coefficients and a bone set from force/torque recordings."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from femstudy.commands.metadata import add_metadata_options, parse_settings
from femstudy.errors import UserError, require

FIGURES = ("fits.png", "power_law.png", "validation.png", "normality.png", "ann_neurons.png")


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
    p.add_argument("--holdout", type=int, default=2,
                   help="replicates held out per condition when no --validate is given (2)")
    add_metadata_options(p, "every recording")
    p.add_argument("--cutoff-hz", type=float, help="low-pass cut-off [Hz] (default from the feed, Table 4-4)")
    p.add_argument("--no-ann", action="store_true", help="skip the neural-network neuron study")
    p.add_argument("--no-figures", action="store_true", help="write tables only")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def recording_paths(items: list[Path], option: str) -> list[Path]:
    """Files as given, folders expanded to their recordings (.csv, .tsv, .txt, .tdms, .mat, .xlsx; sorted)."""
    from femstudy.recordings.reader import RECORDING_SUFFIXES

    paths = []
    for item in items:
        if item.is_dir():
            found = sorted(p for p in item.iterdir() if p.suffix.lower() in RECORDING_SUFFIXES and p.is_file())
            require(found, f"{option}: folder {item} has no recordings ({', '.join(RECORDING_SUFFIXES)} files)")
            paths += found
        else:
            require(item.exists(), f"{option}: recording {item} does not exist")
            paths.append(item)
    names = [p.name for p in paths]
    duplicate = next((n for n in names if names.count(n) > 1), None)
    require(duplicate is None, f"{option}: two recordings are named {duplicate}; names must be unique")
    return paths


def run(args: argparse.Namespace) -> int:
    from femstudy import atomic
    from femstudy.console import Console
    from femstudy.drilling.friction import BUILTIN_TABLES, bone_library
    from femstudy.recordings import figures, read_recording, report
    from femstudy.recordings.pipeline import calibrate
    from femstudy.recordings.processing import process

    console = Console(args.quiet)
    require(re.fullmatch(r"[A-Za-z0-9._-]+", args.name) is not None and not args.name.startswith("."),
            f"--name may contain only letters, digits, '.', '_' and '-', got '{args.name}'")
    require(args.name not in BUILTIN_TABLES, f"--name '{args.name}' is a built-in bone set; choose another name")
    require(args.holdout >= 0, f"--holdout must be >= 0, got {args.holdout}")
    require(args.cutoff_hz is None or args.cutoff_hz > 0, f"--cutoff-hz must be positive, got {args.cutoff_hz}")
    out = args.out if args.out is not None else Path("results") / "calibration" / args.name
    require(not out.exists() or out.is_dir(), f"--out {out} exists and is not a folder")
    settings = parse_settings(args.set)
    cal_paths = recording_paths(args.runs, "RUNS")
    val_paths = recording_paths(args.validate, "--validate")
    clash = {p.name for p in cal_paths} & {p.name for p in val_paths}
    if clash:
        raise UserError(f"{sorted(clash)[0]} is both a calibration and a validation recording")

    recordings = []
    for path in cal_paths + val_paths:
        rec = read_recording(path, settings, override_header=args.override, columns=args.columns)
        for note in rec.notes:
            if "overrides" in note:
                console.warn(f"{path.name}: {note}")
        recordings.append(rec)
    for rec in recordings:
        require(rec.torque_Nmm is not None, f"recording {rec.name} has no torque column (torque_Nmm or torque_Nm); "
                                            f"calibrating mu_f and mu_w needs the torque (Eq 4.4)")
    conditions = sorted({(float(f"{r.feed_mm_s:.6g}"), float(f"{r.spindle_rpm:.6g}"))
                         for r in recordings[: len(cal_paths)]})
    require(len(conditions) >= 4, f"the power law (Eq 4.5) needs calibration runs at four or more (feed, speed) "
                                  f"conditions; these cover {len(conditions)}: "
                                  + ", ".join(f"{f:g} mm/s {n:g} rpm" for f, n in conditions))
    console.progress(f"read {len(recordings)} recordings")
    processed = []
    for k, rec in enumerate(recordings):
        processed.append(process(rec, cutoff_hz=args.cutoff_hz))
        if (k + 1) % 10 == 0 or k + 1 == len(recordings):
            console.progress(f"processed {k + 1}/{len(recordings)} recordings")
    cal, val = processed[: len(cal_paths)], processed[len(cal_paths):]
    result = calibrate(cal, val, name=args.name, holdout=args.holdout,
                       neurons=None if args.no_ann else range(1, 11), progress=console.progress)

    library = bone_library()
    target = library / f"{args.name}.toml"
    text = report.summary_text(result, bone_path=target)
    truth = report.truth_power_law(result)
    with atomic.atomic_folder(out) as tmp:
        atomic.write_text(tmp / "report.txt", text + "\n")
        atomic.write_text(tmp / "runs.csv", report.runs_csv(result))
        atomic.write_text(tmp / "conditions.csv", report.conditions_csv(result))
        atomic.write_text(tmp / f"{args.name}.toml", result.bone.to_toml())
        if result.by_role("held out", "validation"):
            atomic.write_text(tmp / "validation.csv", report.validation_csv(result))
        if result.ann is not None:
            atomic.write_text(tmp / "ann_neurons.csv", report.ann_csv(result))
        if not args.no_figures:
            figures.plot_condition_fits(tmp / "fits.png", result)
            figures.plot_power_law(tmp / "power_law.png", result, truth)
            if result.by_role("held out", "validation"):
                figures.plot_validation(tmp / "validation.png", result)
            if result.normality:
                figures.plot_normality(tmp / "normality.png", result.normality)
            if result.ann is not None:
                figures.plot_neuron_study(tmp / "ann_neurons.png", result.ann)
            console.progress("drew the figures")
    try:
        atomic.write_text(target, result.bone.to_toml())
    except OSError as exc:
        raise UserError(f"cannot save bone set to {target}: {exc.strerror or exc} (the tables are in {out}; "
                        f"set FEMSTUDY_BONES to a writable folder)") from None
    print(text)
    print(f"wrote {out}")
    return 0
