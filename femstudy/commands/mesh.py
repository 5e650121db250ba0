"""``femstudy mesh``: build (or load from the cache) a case's tet mesh and describe it."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.casefile import MAX_MESH_SIZE_MM
from femstudy.commands.options import number


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("mesh", help="tetrahedral femur mesh with regions, quality report and picture",
                       description="Mesh the case's femur with TetWild (or load the cached mesh) and "
                                   "write the mesh, its quality report, detected frame, landmarks and a "
                                   "cut-away picture.")
    p.add_argument("case", type=Path, help="case file (TOML)")
    p.add_argument("--out", type=Path, help="output folder (default results/<case name>-mesh)")
    p.add_argument("--mesh-size", type=number(0, MAX_MESH_SIZE_MM, "mm"), metavar="MM",
                   help="target edge length [mm] (default: mesh.size_mm)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.casefile import load_case, with_overrides
    from femstudy.fe.linsolve import available_memory_bytes
    from femstudy.meshing.model import surface_file
    from femstudy.meshing.report import summary_text
    from femstudy.study.feasibility import check_meshing
    from femstudy.study.femur import femur_spec, mesh_case
    from femstudy.writable import check_output_folder

    case = load_case(args.case, args.settings.bones_dir)
    if args.mesh_size is not None:
        case = with_overrides(case, {"mesh.size_mm": args.mesh_size})
    out = args.out or Path("results") / f"{case.name}-mesh"
    surface = femur_spec(case).surface
    check_output_folder(out, "mesh outputs", inputs=[args.case, *([surface] if surface else [])],
                        cache_dir=args.settings.cache_dir)
    check_meshing(case, surface_file(femur_spec(case), args.settings.cache_dir), available_memory_bytes(),
                  args.settings.cache_dir)
    model = mesh_case(case, out, cache_dir=args.settings.cache_dir)
    print(summary_text(model))
    print(f"\nwrote {out}/: {', '.join(model.stats['written'])}")
    return 0
