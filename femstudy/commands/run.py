"""``femstudy run``: the drilling study for one or more case files."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.errors import require


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the drilling study of one or more case files",
                       description="Mesh the femur (cached), compute the dynamic (chip-clogging) and static "
                                   "Allotta loads, solve, and write results/<case name>/. With several cases, "
                                   "also write a combined table beside the thesis's Tables 5-14/5-15.")
    p.add_argument("cases", type=Path, nargs="+", metavar="CASE.toml")
    p.add_argument("--out", type=Path, help="results folder (one case only; default results/<case name>)")
    p.add_argument("--study-out", type=Path, default=Path("results/study"),
                   help="folder of the combined table when several cases run (results/study)")
    p.add_argument("--mesh-size", type=float, metavar="MM", help="override the case's mesh size [mm]")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.casefile import load_case
    from femstudy.console import Console
    from femstudy.study.run import run_case
    from femstudy.study.study import write_study

    require(args.out is None or len(args.cases) == 1, "--out names one results folder: give one case file")
    require(args.mesh_size is None or args.mesh_size > 0, f"--mesh-size must be positive, got {args.mesh_size}")
    from femstudy.writable import require_writable_parent

    cases = [load_case(path) for path in args.cases]  # validate every file before any work
    for case in cases:
        require_writable_parent(args.out or Path("results") / case.name)
    if len(cases) > 1:
        require_writable_parent(args.study_out)
    console = Console(quiet=args.quiet)
    summaries = []
    for case in cases:
        out = args.out or Path("results") / case.name
        summary = run_case(case, out, mesh_size_mm=args.mesh_size, console=console)
        summaries.append(summary)
        res = summary["results"]
        print(f"{case.name}: max deflection {res['max_deflection_mm']['dynamic']['value']:.4g} mm dynamic / "
              f"{res['max_deflection_mm']['static']['value']:.4g} mm static; max von Mises "
              f"{res['max_von_mises_MPa']['dynamic']['value']:.4g} / {res['max_von_mises_MPa']['static']['value']:.4g} MPa "
              f"({res['max_von_mises_excl_MPa']['dynamic']['value']:.4g} MPa outside the patch zone) -> {out}")
    if len(summaries) > 1:
        path = write_study(args.study_out, summaries)
        print(f"combined table: {path}")
    return 0
