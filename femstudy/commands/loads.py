"""``femstudy loads``: drilling thrust and torque histories of every load model."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.errors import require


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("loads", help="thrust and torque histories of the drilling load models",
                       description="Evaluate the Allotta, chip-clogging, Chi and Peng models for "
                                   "one unicortical hole and print their key values.")
    p.add_argument("--feed", type=float, required=True, metavar="MM_S", help="feed rate f [mm/s]")
    p.add_argument("--rpm", type=float, required=True, help="spindle speed N [rpm]")
    p.add_argument("--bone", default="bovine",
                   help="coefficient set: bovine, human, or a calibrated set name or .toml file")
    p.add_argument("--cortex-mm", type=float, default=6.0, help="cortical thickness [mm] (6)")
    p.add_argument("--diameter-mm", type=float, default=2.7, help="drill diameter D [mm] (2.7)")
    p.add_argument("--point-angle", type=float, default=90.0, metavar="DEG",
                   help="drill point angle beta [deg] (90)")
    p.add_argument("--wall-mm", type=float, default=None,
                   help="wall contact length l_w [mm] (default derived, see docs/load-models.md)")
    p.add_argument("--u1-mpa", type=float, default=None, help="cortical specific cutting energy [MPa]")
    p.add_argument("--u2-mpa", type=float, default=None, help="cancellous specific cutting energy [MPa]")
    p.add_argument("--dt", type=float, default=0.01, help="time step of the histories [s] (0.01)")
    p.add_argument("--csv", type=Path, help="write histories: model,time_s,depth_mm,thrust_N,torque_Nmm")
    p.add_argument("--plot", type=Path, help="write a figure of thrust and torque against time")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from femstudy.drilling import MODELS, Drill, DrillingConditions, evaluate, load_bone_set, time_grid
    from femstudy.drilling import report

    require(args.plot is None or args.plot.suffix.lower() in (".png", ".pdf", ".svg"),
            f"--plot must end in .png, .pdf or .svg, got '{args.plot}'")
    drill = Drill(diameter_mm=args.diameter_mm, point_angle_deg=args.point_angle)
    if args.wall_mm is not None:
        drill = drill.with_(wall_mm=args.wall_mm)
    bone = load_bone_set(args.bone, args.settings.bones_dir)
    for name, value in (("u1_MPa", args.u1_mpa), ("u2_MPa", args.u2_mpa)):
        if value is not None:
            bone = replace(bone, **{name: value})
    cond = DrillingConditions(args.feed, args.rpm, args.cortex_mm, bone, drill)
    if not bone.in_calibrated_range(args.feed, args.rpm):
        import logging

        logging.getLogger("femstudy").warning(f"f = {args.feed:g} mm/s, N = {args.rpm:g} rpm lies outside the "
                                              f"conditions bone set '{bone.name}' was calibrated on; its power law "
                                              "is extrapolated")
    print(report.summary_text(cond, MODELS))
    histories = [evaluate(m, cond, time_grid(cond, args.dt)) for m in MODELS]
    if args.csv:
        report.write_csv(args.csv, histories)
        print(f"\nwrote {args.csv}")
    if args.plot:
        report.plot(args.plot, cond, histories)
        print(f"wrote {args.plot}")
    return 0
