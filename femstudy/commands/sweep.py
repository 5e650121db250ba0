"""``femstudy sweep``: mesh-convergence and parameter sweeps, locally or on a Dask cluster."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.casefile import MAX_MESH_SIZE_MM
from femstudy.commands.options import number, numbers


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="mesh-convergence or parameter sweep",
                       description="With a case file and --sizes: a mesh-convergence study (observed order, "
                                   "Richardson extrapolation, GCI, recommended size). With a sweep file "
                                   "(case = ..., [grid] / [[point]]): the study at every parameter point.")
    p.add_argument("file", type=Path, metavar="CASE_OR_SWEEP.toml")
    p.add_argument("--sizes", type=numbers(0, MAX_MESH_SIZE_MM, "mm"), metavar="MM,MM,...",
                   help="global element sizes [mm], three or more different ones")
    p.add_argument("--order", choices=("1", "2", "both"), default="2", help="element order (2)")
    p.add_argument("--refine", choices=("site", "uniform", "both"), default="site",
                   help="local refinement at the drill site (site)")
    p.add_argument("--target", type=number(0, 1, high_open=True), default=0.02, help="target relative error on max deflection (0.02)")
    p.add_argument("--workers", type=number(1, 256, integer=True, low_open=False), default=1, help="local worker processes (1)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--out", type=Path, help="sweep folder (default results/sweep-<name>)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.sweeps.report import convergence_markdown
    from femstudy.sweeps.run import sweep

    s = args.settings
    result = sweep(args.file, args.sizes, order=args.order, refine=args.refine, target=args.target,
                   workers=args.workers, scheduler=args.scheduler, out=args.out, cache_dir=s.cache_dir,
                   solver=s.solver, bones_dir=s.bones_dir)
    if result.kind == "mesh":
        print(convergence_markdown(result.convergence, args.target))
    else:
        from femstudy.sweeps.report import table_markdown

        print(table_markdown(result.rows, result.columns))
    print(f"wrote {result.folder / 'sweep.md'}")
    return 0
