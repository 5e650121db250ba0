"""``femstudy femur``: write the built-in left femur surface (deterministic STL)."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.commands.options import number
from femstudy.meshing.builtin_femur import FemurParameters

_HELP = {
    "length_mm": "length, top of head to bottom of condyles [mm]",
    "head_diameter_mm": "femoral head diameter [mm]",
    "neck_shaft_angle_deg": "neck-shaft angle [deg]",
    "anteversion_deg": "femoral neck anteversion [deg]",
    "shaft_diameter_mm": "mid-shaft outer diameter [mm]",
    "bow_mm": "anterior bow of the shaft, sagitta [mm]",
    "offset_mm": "femoral offset, head centre to shaft axis [mm]",
    "resolution_mm": "sampling grid of the implicit shape [mm]",
    "triangles": "triangles in the written surface",
}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("femur", help="write the built-in left femur surface (STL)",
                       description="Generate the built-in adult left femur from anatomical parameters "
                                   "and write it as a binary STL; the same parameters always give the "
                                   "same bytes.")
    p.add_argument("--out", type=Path, default=Path("meshes/femur_left_medium.stl"),
                   help="output STL (default meshes/femur_left_medium.stl)")
    defaults = FemurParameters()
    for name, text in _HELP.items():
        value = getattr(defaults, name)
        p.add_argument("--" + name.replace("_", "-"), type=number(integer=isinstance(value, int)), default=value,
                       help=f"{text} ({value:g})")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.errors import require
    from femstudy.meshing.builtin_femur import write_femur
    from femstudy.writable import check_output_file

    require(args.out.suffix.lower() == ".stl", f"--out must end in .stl, got '{args.out}'")
    check_output_file(args.out, "the femur surface")
    par = FemurParameters(**{name: getattr(args, name) for name in _HELP})
    surf = write_femur(args.out, par)  # written through a link (meshes/ links to the packaged file)
    print(f"wrote {args.out}: {surf.n_cells} triangles, {surf.n_points} points, volume {surf.volume:.0f} mm^3, "
          f"length {surf.bounds[5] - surf.bounds[4]:.1f} mm, parameters {par.digest()}")
    return 0
