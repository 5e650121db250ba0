"""``femstudy run``: the drilling study for one or more case files."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.casefile import MAX_MESH_SIZE_MM
from femstudy.commands.options import number


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the drilling study of one or more case files",
                       description="Mesh the femur (cached), compute the dynamic (chip-clogging) and static "
                                   "Allotta loads, solve, and write results/<case name>/. With several cases, "
                                   "also write a combined table beside the thesis's Tables 5-14/5-15.")
    p.add_argument("cases", type=Path, nargs="+", metavar="CASE.toml")
    p.add_argument("--out", type=Path, help="results folder (one case only; default results/<case name>)")
    p.add_argument("--study-out", type=Path, default=Path("results/study"),
                   help="folder of the combined table when several cases run (results/study)")
    p.add_argument("--mesh-size", type=number(0, MAX_MESH_SIZE_MM, "mm"), metavar="MM",
                   help="override the case's mesh size [mm]")
    p.add_argument("--bone", metavar="NAME", help="friction calibration for every case: human, human-printed, "
                                                 "bovine or a calibrated set (default: each case's)")
    p.add_argument("--force", action="store_true",
                   help="run a study estimated to take very long, or one whose inputs or results fail a plausibility "
                        "check (docs/checks.md); such results are marked out of range in report.md and summary.json")
    p.add_argument("--no-kept-solutions", dest="keep_solutions", action="store_false",
                   help="factorise even when an earlier run kept the solutions of the same stiffness "
                        "matrices (in the cache folder; docs/solver.md)")
    p.add_argument("--serial", dest="parallel", action="store_false",
                   help="run every part of the study in this process (by default the hole models and the "
                        "writing of figures and fields run in forked processes beside the global analyses)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.lanes import Lanes
    from femstudy.study.study import run_cases

    s = args.settings
    results, table = run_cases(args.cases, out=args.out, study_out=args.study_out, mesh_size_mm=args.mesh_size,
                               cache_dir=s.cache_dir, solver=s.solver, bones_dir=s.bones_dir,
                               bone=args.bone, force=args.force, keep_solutions=args.keep_solutions,
                               executor=Lanes() if args.parallel else None)
    for r in results:
        d, st = r.dynamic.peaks, r.static.peaks
        if r.hole is not None:
            distance = r.hole.options.headline_distance_mm
            stress = (f"von Mises {distance:g} mm from the hole {r.hole.headline('dynamic').von_mises_MPa:.4g} / "
                      f"{r.hole.headline('static').von_mises_MPa:.4g} MPa")
        else:
            stress = (f"max von Mises under the patch {d['max_von_mises_MPa'].value:.4g} / "
                      f"{st['max_von_mises_MPa'].value:.4g} MPa")
        marked = " [OUT OF RANGE (--force): see report.md]" if r.out_of_range else ""
        print(f"{r.case.name}: max deflection {d['max_deflection_mm'].value:.4g} mm dynamic / "
              f"{st['max_deflection_mm'].value:.4g} mm static; {stress} -> {r.out_dir}{marked}")
    if table is not None:
        print(f"combined table: {table}")
    return 0
