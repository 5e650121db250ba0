"""``femstudy synth``: synthetic force/torque recordings, one file or a calibration data set."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.commands.options import number
from femstudy.drilling import registry
from femstudy.recordings.formats import registry as formats
from femstudy.recordings.synthetic import EFFECT_OPTIONS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("synth", help="synthetic force/torque recordings from the load models",
                       description="Write a synthetic recording (approach, contact, cutting, breakthrough, "
                                   "retraction) with noise, spindle ripple, feed pulsation, sensor drift and "
                                   "thermal softening, or a calibration data set (--dataset); the effects and "
                                   "the ground truth go into the header.")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", type=Path, help="write one recording (format from --format, else the suffix)")
    where.add_argument("--dataset", type=Path, metavar="DIR", help="write a calibration data set "
                       "(Table 4-1 conditions x replicates, validation runs at Table 5-3 conditions)")
    p.add_argument("--feed", type=number(0.01, 50, "mm/s", low_open=False), default=1.5, metavar="MM_S", help="feed rate f [mm/s] (1.5)")
    p.add_argument("--rpm", type=number(10, 100_000, "rpm", low_open=False), default=1500.0, help="spindle speed N [rpm] (1500)")
    p.add_argument("--cortex-mm", type=number(0, 20, "mm"), default=6.0, help="cortical thickness [mm] (6)")
    p.add_argument("--model", choices=registry.names("synthesis"), default="clogging", help="(clogging)")
    p.add_argument("--bone", default="bovine", help="bone set giving friction and cutting energies (bovine)")
    p.add_argument("--mu-f", type=number(0, 5), help="flute friction mu_f (default: the bone set at f, N)")
    p.add_argument("--mu-w", type=number(0, 10), help="wall friction mu_w (default: the bone set at f, N)")
    p.add_argument("--u1-mpa", type=number(0, 10_000, "MPa"), help="cortical specific cutting energy [MPa]")
    p.add_argument("--rate-hz", type=number(100, 10_000, "Hz", low_open=False), default=1000.0, help="sampling rate [Hz] (1000)")
    p.add_argument("--approach-s", type=number(0, 600, "s"), default=2.0, help="time before contact [s] (2)")
    p.add_argument("--stop-depth-mm", type=number(0, 100, "mm"), help="depth where the feed stops (cortex + 2 mm; "
                                                      "less than the cortex ends the cut by retraction)")
    p.add_argument("--seed", type=int, default=0, help="random seed (0)")
    p.add_argument("--format", choices=list(formats.writers()), help="file format (default: from the suffix, else csv)")
    p.add_argument("--time-unit", default="s", help="time column unit, e.g. s or ms (s)")
    p.add_argument("--force-unit", default="N", help="thrust column unit, e.g. N, kN or lbf (N)")
    p.add_argument("--torque-unit", default="Nmm", help="torque column unit, e.g. Nmm, N*m or lbf*in (Nmm)")
    p.add_argument("--depth-column", action="store_true", help="also write the tip depth depth_mm")
    p.add_argument("--clean", action="store_true", help="switch every effect off unless given below")
    effects = p.add_argument_group("effects (0 switches an effect off; drift rates may be negative)")
    for option, _, _, default, text in EFFECT_OPTIONS:
        effects.add_argument(f"--{option}", type=number(-1e6, 1e6), dest=option, help=f"{text} ({default:g})")
    effects.add_argument("--pulsation-shape", choices=("sine", "pulse"), default="sine", help="(sine)")
    p.add_argument("--replicates", type=number(1, 1000, integer=True, low_open=False), default=10, help="--dataset: runs per condition (10)")
    p.add_argument("--outliers", type=number(0, 1000, integer=True, low_open=False), default=3, help="--dataset: outlier runs (3)")
    p.add_argument("--plot", type=Path, help="--out: also draw the recording (PNG/PDF/SVG)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.recordings.dataset import write_dataset, write_synthetic
    from femstudy.recordings.synthetic import Effects

    from femstudy.casefile import MAX_FEED_PER_REV_MM
    from femstudy.errors import require
    from femstudy.writable import check_output_file, check_output_folder

    turn_mm = 60.0 * args.feed / args.rpm
    require(turn_mm <= MAX_FEED_PER_REV_MM, f"--feed {args.feed:g} mm/s at --rpm {args.rpm:g} advances the drill "
                                            f"{turn_mm:.3g} mm per turn; a twist drill cuts at most "
                                            f"{MAX_FEED_PER_REV_MM:g} mm per turn (surgical drilling: 0.01-0.2 mm)")
    if args.dataset:
        check_output_folder(args.dataset, "the data set", cache_dir=args.settings.cache_dir)
        print(write_dataset(args.dataset, bone=args.bone, replicates=args.replicates, outliers=args.outliers,
                            seed=args.seed, sample_rate_hz=args.rate_hz, torque_unit=args.torque_unit,
                            format=args.format))
        return 0
    check_output_file(args.out, "the recording")
    if args.plot is not None:
        check_output_file(args.plot, "the figure", inputs=[args.out])
    effects = Effects.from_options({o[0]: getattr(args, o[0]) for o in EFFECT_OPTIONS}, args.clean,
                                   args.pulsation_shape)
    print(write_synthetic(args.out, format=args.format, time_unit=args.time_unit, force_unit=args.force_unit,
                          torque_unit=args.torque_unit, plot=args.plot, feed_mm_s=args.feed,
                          spindle_rpm=args.rpm, cortex_mm=args.cortex_mm, bone=args.bone, mu_f=args.mu_f,
                          mu_w=args.mu_w, u1_MPa=args.u1_mpa, model=args.model, sample_rate_hz=args.rate_hz,
                          approach_s=args.approach_s, stop_depth_mm=args.stop_depth_mm, effects=effects,
                          seed=args.seed, depth_column=args.depth_column))
    return 0
