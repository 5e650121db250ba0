"""``femstudy mesh``: build (or load from the cache) a case's tet mesh and describe it."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("mesh", help="tetrahedral femur mesh with regions, quality report and picture",
                       description="Mesh the case's femur with TetWild (or load the cached mesh) and "
                                   "write the mesh, its quality report, detected frame, landmarks and a "
                                   "cut-away picture.")
    p.add_argument("case", type=Path, help="case file (TOML)")
    p.add_argument("--out", type=Path, help="output folder (default results/<case name>-mesh)")
    p.add_argument("--mesh-size", type=float, metavar="MM", help="target edge length [mm] (default: mesh.size_mm)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy import atomic
    from femstudy.casefile import load_case
    from femstudy.console import Console
    from femstudy.errors import require
    from femstudy.meshing import build_femur_model
    from femstudy.meshing.report import summary_text, write_outputs

    require(args.mesh_size is None or args.mesh_size > 0, f"--mesh-size must be positive, got {args.mesh_size}")
    case = load_case(args.case)
    console = Console(quiet=args.quiet)
    model = build_femur_model(case, console, mesh_size_mm=args.mesh_size)
    out = args.out or Path("results") / f"{case.name}-mesh"
    console.progress(f"writing {out}")
    with atomic.atomic_folder(out) as tmp:
        names = write_outputs(model, tmp, screenshot=case.output.screenshot)
    print(summary_text(model))
    print(f"\nwrote {out}/: {', '.join(names)}")
    return 0
