"""Sizes of the drilled-hole local model on a femur: DOFs per station at each refinement.

For a case's femur (mesh from the cache when it is there), build the local model around the
drill axis at refinements 1, 1.5 and 2.25 with stations every ``--step`` mm of tip depth
until the cone's corner reaches the case's hole depth, and print per level: the mesh time, points,
tetrahedra, minimum dihedral angle, and the P2 DOFs of every station (3 × (vertices + edges)
of its tetrahedra). With ``--solve``, also assemble and factorise one station per level with
the cut boundary prescribed (wall times, the factor's method and, for PARDISO, its planned
memory); one heavy job at a time. Times are wall-clock on a shared machine: expect noise.

    FEMSTUDY_CACHE=... PYTHONPATH=. python bench/hole_sizes.py cases/middiaphysis.toml [--solve]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from femstudy.casefile import load_case  # noqa: E402
from femstudy.fe import assemble  # noqa: E402
from femstudy.hole import (HoleFrame, Resolution, facet_indices, facet_nodes, factorize_prescribed,  # noqa: E402
                           hole_mesh, node_dofs)
from femstudy.hole.femur import femur_columns  # noqa: E402
from femstudy.study.femur import femur_model  # noqa: E402
from femstudy.meshing.landmarks import outer_faces  # noqa: E402


def p2_dofs(tets: np.ndarray) -> int:
    edges = np.sort(tets[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]].reshape(-1, 2), axis=1)
    return 3 * (len(np.unique(tets)) + len(np.unique(edges, axis=0)))


def add_femur_arguments(parser: argparse.ArgumentParser) -> None:
    """The case and the local model's placement, shared with bench/hole_convergence.py."""
    parser.add_argument("case")
    parser.add_argument("--submodel-radius", type=float, default=8.0, help="R_sub [mm]")
    parser.add_argument("--depth-cap", type=float, default=12.0, help="deepest column below its top [mm]")
    parser.add_argument("--step", type=float, default=1.0, help="station spacing in tip depth [mm]")
    parser.add_argument("--levels", type=float, nargs="+", default=[1.0, 1.5, 2.25])


def femur_hole(args):
    """(case, a function refinement → HoleMesh, station tip depths) for the case's femur."""
    case = load_case(args.case)
    model = femur_model(case)
    frame = HoleFrame.along(model.site.entry_point, model.site.direction)
    columns = femur_columns(model.mesh, outer_faces(model.mesh, model.frame), frame, args.depth_cap)
    diameter, angle = case.drill.diameter_mm, case.drill.point_angle_deg
    cone = diameter / 2 / np.tan(np.radians(angle) / 2)
    tips = np.arange(args.step, case.drilling.depth_mm + cone + 1e-9, args.step)

    def build(level: float):
        return hole_mesh(frame, diameter, angle, args.submodel_radius, tips, columns.top, columns.bottom,
                         columns.region, Resolution(refinement=level))

    print(f"{case.name}: cortex {model.site.cortical_thickness_mm:.2f} mm along the drill, R_sub "
          f"{args.submodel_radius} mm, depth cap {args.depth_cap} mm, {len(tips)} stations (tips {tips[0]:g}.."
          f"{tips[-1]:g} mm)")
    return case, build, tips


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_femur_arguments(parser)
    parser.add_argument("--solve", action="store_true", help="assemble and factorise the deepest station per level")
    args = parser.parse_args()
    case, build, tips = femur_hole(args)
    for level in args.levels:
        start = time.perf_counter()
        hole = build(level)
        seconds = time.perf_counter() - start
        dofs = [p2_dofs(hole.at_station(k).mesh.tets) for k in range(hole.n_stations)]
        s = hole.summary()
        print(f"refinement {level:g}: mesh {seconds:.1f} s, {s['n_points']:,} points, {s['n_tets']:,} tets, "
              f"{s['n_wall']} on the hole circle, {s['n_layers']} layers, min dihedral {s['min_dihedral_deg']:.1f}°")
        print("  P2 DOFs per station: " + ", ".join(f"{d:,}" for d in dofs))
        if args.solve:
            station = hole.at_station(hole.n_stations - 1)
            start = time.perf_counter()
            system = assemble(station.mesh, case.materials.to_fe(), order=2)
            assembled = time.perf_counter() - start
            cut = facet_nodes(system, facet_indices(system, station.cut_faces))
            dofs = node_dofs(cut).ravel()
            factor = factorize_prescribed(system, dofs).fs.factor
            planned = getattr(factor, "planned_bytes", None)
            memory = f", factor {planned / 2**30:.2f} GiB planned" if planned else ""
            print(f"  deepest station: {system.n_dofs:,} DOFs, assembly {assembled:.1f} s, {factor.describe()}{memory}")


if __name__ == "__main__":
    main()
