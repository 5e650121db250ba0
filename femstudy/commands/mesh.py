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
    from femstudy.casefile import load_case
    from femstudy.meshing.report import summary_text
    from femstudy.study.femur import mesh_case

    case = load_case(args.case, args.settings.bones_dir)
    out = args.out or Path("results") / f"{case.name}-mesh"
    model = mesh_case(case, out, mesh_size_mm=args.mesh_size, cache_dir=args.settings.cache_dir)
    print(summary_text(model))
    print(f"\nwrote {out}/: {', '.join(model.stats['written'])}")
    return 0
