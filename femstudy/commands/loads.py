"""``femstudy loads``: drilling thrust and torque histories of every load model."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.commands.options import number


#: Most samples of one model's history (a long cut at a fine --dt would fill memory).
MAX_SAMPLES = 1_000_000


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("loads", help="thrust and torque histories of the drilling load models",
                       description="Evaluate the Allotta, chip-clogging, Chi and Peng models for "
                                   "one unicortical hole and print their key values.")
    p.add_argument("--feed", type=number(0.01, 50, "mm/s", low_open=False), required=True, metavar="MM_S", help="feed rate f [mm/s]")
    p.add_argument("--rpm", type=number(10, 100_000, "rpm", low_open=False), required=True, help="spindle speed N [rpm]")
    p.add_argument("--bone", default="bovine",
                   help="coefficient set: bovine, human, or a calibrated set name or .toml file")
    p.add_argument("--cortex-mm", type=number(0, 20, "mm"), default=6.0, help="cortical thickness [mm] (6)")
    p.add_argument("--diameter-mm", type=number(0, 20, "mm"), default=2.7, help="drill diameter D [mm] (2.7)")
    p.add_argument("--point-angle", type=number(0, 180, "degrees", high_open=True), default=90.0, metavar="DEG",
                   help="drill point angle beta [deg] (90)")
    p.add_argument("--wall-mm", type=number(0, 20, "mm"), default=None,
                   help="wall contact length l_w [mm] (default derived, see docs/load-models.md)")
    p.add_argument("--u1-mpa", type=number(0, 10_000, "MPa"), default=None, help="cortical specific cutting energy [MPa]")
    p.add_argument("--u2-mpa", type=number(0, 10_000, "MPa", low_open=False), default=None, help="cancellous specific cutting energy [MPa]")
    p.add_argument("--dt", type=number(1e-5, 1, "s", low_open=False), default=0.01, help="time step of the histories [s] (0.01)")
    p.add_argument("--csv", type=Path, help="write histories: model,time_s,depth_mm,thrust_N,torque_Nmm")
    p.add_argument("--plot", type=Path, help="write a figure of thrust and torque against time")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.casefile import MAX_FEED_PER_REV_MM
    from femstudy.drilling import Drill
    from femstudy.drilling.report import load_models, plot, write_csv
    from femstudy.errors import require
    from femstudy.writable import check_output_file

    turn_mm = 60.0 * args.feed / args.rpm
    require(turn_mm <= MAX_FEED_PER_REV_MM, f"--feed {args.feed:g} mm/s at --rpm {args.rpm:g} advances the drill "
                                            f"{turn_mm:.3g} mm per turn; a twist drill cuts at most "
                                            f"{MAX_FEED_PER_REV_MM:g} mm per turn (surgical drilling: 0.01-0.2 mm)")
    cut_s = (args.cortex_mm + Drill(diameter_mm=args.diameter_mm, point_angle_deg=args.point_angle).cone_length_mm) \
        / args.feed
    require(cut_s / args.dt <= MAX_SAMPLES, f"--dt {args.dt:g} s over the {cut_s:.4g} s of the cut makes "
                                            f"{cut_s / args.dt:,.0f} samples per model; at most {MAX_SAMPLES:,}: "
                                            "use a longer --dt")
    for path, what in ((args.csv, "the histories"), (args.plot, "the figure")):
        if path is not None:
            check_output_file(path, what)
    study = load_models(args.feed, args.rpm, bone=args.bone, cortex_mm=args.cortex_mm, diameter_mm=args.diameter_mm,
                        point_angle_deg=args.point_angle, wall_mm=args.wall_mm, u1_MPa=args.u1_mpa,
                        u2_MPa=args.u2_mpa, dt_s=args.dt, bones_dir=args.settings.bones_dir)
    _require_drill_loads(study)
    if args.csv:
        write_csv(args.csv, study.histories)
    if args.plot:
        plot(args.plot, study.conditions, study.histories)
    print(study.text)
    if args.csv:
        print(f"\nwrote {args.csv}")
    if args.plot:
        print(f"wrote {args.plot}")
    return 0


def _require_drill_loads(study) -> None:
    """Refuse load histories that no drill in bone exerts (beyond the bounds of a drilling
    recording, femstudy.recordings.ranges) or that are not finite (NaN marks a model
    without torque, and is skipped)."""
    import numpy as np

    from femstudy.errors import UserError
    from femstudy.recordings.ranges import MAX_MAGNITUDE

    for h in study.histories:
        for what, unit, values, limit in (("thrust", "N", h.thrust_N, MAX_MAGNITUDE["thrust"]),
                                          ("torque", "N·mm", h.torque_Nmm, MAX_MAGNITUDE["torque"])):
            values = np.asarray(values, float)
            values = values[~np.isnan(values)]
            if values.size and not (np.all(np.isfinite(values)) and np.abs(values).max() <= limit):
                raise UserError(f"the {h.model} model's {what} reaches {np.abs(values).max():.3g} {unit}, beyond the "
                                f"{limit:g} {unit} any drill in bone exerts: the friction law, the energies or the "
                                "operating point are outside what the models describe")
