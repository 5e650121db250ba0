"""``femstudy synth``: synthetic force/torque recordings, one file or a calibration data set."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.errors import require

#: the formats of femstudy.recordings.reader.WRITE_FORMATS (listed here to keep --help import-free)
FORMATS = ("csv", "csv-semicolon", "tsv", "decimal-comma", "excel-csv", "dynoware", "tdms", "mat", "mat73", "xlsx")

#: (option, Effects field, parameter, default) of every switchable effect; 0 switches it off.
EFFECT_OPTIONS = [
    ("--noise-thrust-N", "noise", "thrust_N", 0.3, "Gaussian thrust noise, standard deviation [N]"),
    ("--noise-torque-Nmm", "noise", "torque_Nmm", 1.0, "Gaussian torque noise, standard deviation [N.mm]"),
    ("--ripple", "ripple", "fraction", 0.05, "spindle-frequency ripple, fraction of the load"),
    ("--pulsation", "pulsation", "amplitude", 0.2, "feed pulsation amplitude, fraction of the feed"),
    ("--pulsation-hz", "pulsation", "frequency_hz", 1.0, "feed pulsation frequency [Hz]"),
    ("--drift-N-per-s", "drift", "thrust_N_per_s", 0.05, "thrust sensor drift [N/s]"),
    ("--drift-Nmm-per-s", "drift", "torque_Nmm_per_s", 0.2, "torque sensor drift [N.mm/s]"),
    ("--softening", "softening", "fraction", 0.0, "thermal softening: final fractional load loss"),
    ("--softening-s", "softening", "time_constant_s", 2.0, "thermal softening time constant [s]"),
]
#: the parameter that switches each effect on or off (0 = off)
SWITCHES = {"noise": ("thrust_N", "torque_Nmm"), "ripple": ("fraction",), "pulsation": ("amplitude",),
            "drift": ("thrust_N_per_s", "torque_Nmm_per_s"), "softening": ("fraction",)}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("synth", help="synthetic force/torque recordings from the load models",
                       description="Write a realistic synthetic recording (approach, contact, cutting, "
                                   "breakthrough, retraction) with noise, spindle ripple, feed pulsation, "
                                   "sensor drift and thermal softening, or a five-condition calibration "
                                   "data set (--dataset). Every effect and the ground truth go into the "
                                   "header.")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", type=Path, help="write one recording (format from --format, else from the suffix)")
    where.add_argument("--dataset", type=Path, metavar="DIR",
                       help="write a calibration data set: Table 4-1 conditions x replicates, plus "
                            "validation runs at the Table 5-3 conditions")
    p.add_argument("--feed", type=float, default=1.5, metavar="MM_S", help="feed rate f [mm/s] (1.5)")
    p.add_argument("--rpm", type=float, default=1500.0, help="spindle speed N [rpm] (1500)")
    p.add_argument("--cortex-mm", type=float, default=6.0, help="cortical thickness [mm] (6)")
    p.add_argument("--model", choices=("clogging", "allotta"), default="clogging",
                   help="cutting with chip clogging, or cutting alone (clogging)")
    p.add_argument("--bone", default="bovine", help="bone set giving friction and cutting energies (bovine)")
    p.add_argument("--mu-f", type=float, help="flute friction mu_f (default: the bone set at f, N)")
    p.add_argument("--mu-w", type=float, help="wall friction mu_w (default: the bone set at f, N)")
    p.add_argument("--u1-mpa", type=float, help="cortical specific cutting energy [MPa]")
    p.add_argument("--rate-hz", type=float, default=1000.0, help="sampling rate [Hz] (1000)")
    p.add_argument("--approach-s", type=float, default=2.0, help="time before contact [s] (2)")
    p.add_argument("--stop-depth-mm", type=float,
                   help="depth where the feed stops (default cortex + 2 mm; less than the cortex "
                        "ends the cut by retraction)")
    p.add_argument("--seed", type=int, default=0, help="random seed (0)")
    p.add_argument("--format", choices=FORMATS,
                   help="file format: csv, csv-semicolon, tsv, decimal-comma (';' and ','), excel-csv (also a "
                        "byte-order mark and CRLF), dynoware (Kistler-like text export), tdms, mat, mat73 (HDF5), "
                        "xlsx (default: from the --out suffix, else csv)")
    p.add_argument("--time-unit", default="s", help="time column unit, e.g. s or ms (s)")
    p.add_argument("--force-unit", default="N", help="thrust column unit, e.g. N, kN or lbf (N)")
    p.add_argument("--torque-unit", default="Nmm", help="torque column unit, e.g. Nmm, N*m or lbf*in (Nmm)")
    p.add_argument("--depth-column", action="store_true", help="also write the tip depth depth_mm")
    p.add_argument("--clean", action="store_true", help="switch every effect off unless given below")
    effects = p.add_argument_group("effects (0 switches an effect off; drift rates may be negative)")
    for option, _, _, default, text in EFFECT_OPTIONS:
        effects.add_argument(option, type=float, default=None, help=f"{text} ({default:g})")
    effects.add_argument("--pulsation-shape", choices=("sine", "pulse"), default="sine",
                         help="feed pulsation waveform (sine)")
    p.add_argument("--replicates", type=int, default=10, help="--dataset: runs per condition (10)")
    p.add_argument("--outliers", type=int, default=3, help="--dataset: outlier runs (3)")
    p.add_argument("--plot", type=Path, help="--out: also draw the recording (PNG/PDF/SVG)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def effects_from_args(args) -> "Effects":
    """The Effects the options ask for: defaults unless --clean, 0 switches off."""
    from dataclasses import replace

    from femstudy.recordings.synthetic import (Effects, FeedPulsation, Noise, SensorDrift, SpindleRipple,
                                               ThermalSoftening)

    classes = {"noise": Noise, "ripple": SpindleRipple, "pulsation": FeedPulsation, "drift": SensorDrift,
               "softening": ThermalSoftening}
    values: dict[str, dict] = {name: {} for name in classes}
    for option, group, field, default, _ in EFFECT_OPTIONS:
        given = getattr(args, option.lstrip("-").replace("-", "_"))
        require(given is None or given >= 0 or group == "drift", f"{option} must be >= 0, got {given}")
        values[group][field] = given if given is not None else (0.0 if args.clean else default)
    values["pulsation"]["shape"] = args.pulsation_shape
    chosen = {}
    for name, cls in classes.items():
        on = any(values[name][f] != 0 for f in SWITCHES[name])
        chosen[name] = replace(cls(), **values[name]) if on else None
    return Effects(**chosen)


def run(args: argparse.Namespace) -> int:
    from femstudy.console import Console
    from femstudy.recordings import synthesize, write_recording

    console = Console(args.quiet)
    if args.dataset:
        from femstudy.recordings.dataset import write_dataset

        require(args.replicates >= 1, f"--replicates must be at least 1, got {args.replicates}")
        summary = write_dataset(args.dataset, bone=args.bone, replicates=args.replicates,
                                outliers=args.outliers, seed=args.seed, sample_rate_hz=args.rate_hz,
                                torque_unit=args.torque_unit, format=args.format, progress=console.progress)
        print(summary)
        return 0
    require(args.plot is None or args.plot.suffix.lower() in (".png", ".pdf", ".svg"),
            f"--plot must end in .png, .pdf or .svg, got '{args.plot}'")
    rec = synthesize(args.feed, args.rpm, cortex_mm=args.cortex_mm, bone=args.bone, mu_f=args.mu_f,
                     mu_w=args.mu_w, u1_MPa=args.u1_mpa, model=args.model, sample_rate_hz=args.rate_hz,
                     approach_s=args.approach_s, stop_depth_mm=args.stop_depth_mm,
                     effects=effects_from_args(args), seed=args.seed, depth_column=args.depth_column)
    write_recording(args.out, rec, args.torque_unit, format=args.format, time_unit=args.time_unit,
                    force_unit=args.force_unit)
    m = rec.metadata
    print(f"wrote {args.out}: {rec.time_s.size} samples at {args.rate_hz:g} Hz, {rec.duration_s:.2f} s; "
          f"model {m['model']}, mu_f = {m['true_mu_f']:.4f}, mu_w = {m['true_mu_w']:.4f}, "
          f"F_o = {m['true_initial_force_N']:.2f} N; effects: {', '.join(m['effects']) or 'none'}")
    if args.plot:
        from dataclasses import replace

        from femstudy.recordings.figures import plot_recording

        plot_recording(args.plot, replace(rec, source=str(args.out)))
        print(f"wrote {args.plot}")
    return 0
