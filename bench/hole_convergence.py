"""Convergence of the stresses near the drilled hole of a femur's local model.

For a case's femur, build the local model (R_sub, stations every ``--step`` mm of tip depth)
at refinements 1, 1.5 and 2.25, take one station, hold its cut boundary fixed (u = 0: a
stand-in for the global model's displacements, which the coupling supplies) and apply each
unit hole load in turn — cutting thrust 1 N, cutting torque 1 N·mm, chip-evacuation torque
1 N·mm with growth exponent ``--growth`` — and report, per load and per distance δ from the
hole surface, the largest von Mises stress over the offset sample set, then the observed
order, extrapolated value and GCI of the three levels (femstudy.sweep.convergence, formal
order 2 for P2 stresses, h ∝ 1/refinement). One heavy job: the finest level has ~0.7M DOFs.

    FEMSTUDY_CACHE=... PYTHONPATH=. python bench/hole_convergence.py cases/middiaphysis.toml --tip 4
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.hole_sizes import add_femur_arguments, femur_hole  # noqa: E402
from femstudy.fe import assemble, von_mises  # noqa: E402
from femstudy.hole import (facet_indices, facet_nodes, hole_loads, node_dofs, offset_samples,  # noqa: E402
                           point_probe, solve_prescribed)
from femstudy.sweeps.convergence import assess  # noqa: E402

LOADS = ("cutting_thrust", "cutting_torque", "evacuation_torque")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_femur_arguments(parser)
    parser.add_argument("--tip", type=float, default=4.0, help="drill-tip depth of the station [mm]")
    parser.add_argument("--growth", type=float, default=0.47, help="chip-pressure growth exponent p")
    parser.add_argument("--distances", type=float, nargs="+", default=[0.5, 1.0, 2.0, 5.0])
    args = parser.parse_args()
    case, build, tips = femur_hole(args)
    k = int(np.argmin(np.abs(tips - args.tip)))
    print(f"station {k} (tip {tips[k]:g} mm), cut boundary fixed, unit loads {', '.join(LOADS)} (p = {args.growth:g})")
    maxima = {}  # (load, δ) -> values per level
    for level in args.levels:
        start = time.perf_counter()
        hole = build(level)
        station = hole.at_station(k)
        system = assemble(station.mesh, case.materials.to_fe(), order=2)
        loads = hole_loads(system, station, growth_exponent=args.growth)
        cut = node_dofs(facet_nodes(system, facet_indices(system, station.cut_faces))).ravel()
        u = solve_prescribed(system, cut, np.zeros(len(cut)), np.column_stack([getattr(loads, n) for n in LOADS]))
        solved = time.perf_counter() - start
        row = []
        for delta in args.distances:
            samples = offset_samples(station, delta)
            found = point_probe(system, samples.points)
            vm = von_mises(found.stress(u))  # (points, loads)
            for j, name in enumerate(LOADS):
                maxima.setdefault((name, delta), []).append(float(np.nanmax(vm[:, j])))
            row.append(f"δ={delta:g}: {found.inside.sum():,}/{len(samples.points):,} samples in bone")
        print(f"refinement {level:g}: {system.n_dofs:,} DOFs, mesh+assembly+solve {solved:.0f} s; " + "; ".join(row),
              flush=True)
    print("\n| load | δ [mm] | max von Mises [MPa per unit load], refinement " + ", ".join(f"{v:g}" for v in args.levels)
          + " | observed order | extrapolated | GCI fine | verdict |")
    print("|---|---|---|---|---|---|---|")
    for (name, delta), values in maxima.items():
        line = ", ".join(f"{v:.4g}" for v in values)
        if len(values) >= 3:
            a = assess(f"{name} δ={delta:g}", [1 / v for v in args.levels], values, expected_order=2.0)
            p = "—" if a.observed_order is None else f"{a.observed_order:.2f}"
            ext = "—" if a.extrapolated is None else f"{a.extrapolated:.4g}"
            gci = "—" if a.gci_fine is None else f"{100 * a.gci_fine:.2f} %"
            print(f"| {name} | {delta:g} | {line} | {p} | {ext} | {gci} | {a.verdict} |")
        else:
            print(f"| {name} | {delta:g} | {line} | | | | |")


if __name__ == "__main__":
    main()
