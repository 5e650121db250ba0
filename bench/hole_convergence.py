"""Convergence of the hole-based stresses of a study case (docs/hole.md).

The case's global femur model (mesh at ``--mesh-size`` or the case's size, from the cache)
is solved once for a unit patch thrust and torque; :func:`femstudy.hole.study.hole_stresses`
then runs the coupled hole models (global displacements on the cut faces, drill loads on the
hole) at the case's stations for each hole refinement of ``--levels``, and the largest dynamic
von Mises stress over the stations at each distance from the hole wall and beyond each
exclusion radius is assessed by femstudy.convergence (formal order 2 for P2 stresses,
mesh measure the hole model's wall element size 0.3 mm / refinement), against the placement
noise: the case's own level once more with the local mesh turned about the drill axis by half a
hole-circle step (the analogue of remeshing one size with TetWild: same resolution, other
element positions). One heavy job: the finest default level has ~0.2M DOFs per station.

    PYTHONPATH=. python bench/hole_convergence.py cases/middiaphysis.toml [--mesh-size 16] [--levels 0.6667 1 1.5]
        [--json cases/convergence/middiaphysis-hole.json]

``--json`` writes the verdicts for the case's own level (``loads.refinement``, one of the
levels) as a record a case names in
``loads.convergence`` (femstudy/study/verdicts.py), so that its failure margins use only
converged measures.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from femstudy.atomic import write_text  # noqa: E402
from femstudy.casefile import load_case, with_overrides  # noqa: E402
from femstudy.study import verdicts  # noqa: E402
from femstudy.hole.mesh import Resolution  # noqa: E402
from femstudy.hole.study import hole_stresses  # noqa: E402
from femstudy.jsonable import jsonable  # noqa: E402
from femstudy.study.global_model import prepare  # noqa: E402
from femstudy.study.loading import case_loading  # noqa: E402
from femstudy.convergence import assess  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("case")
    parser.add_argument("--mesh-size", type=float, default=None, help="global element size [mm]")
    parser.add_argument("--levels", type=float, nargs="+", default=[2 / 3, 1.0, 1.5],
                        help="hole refinements (one of them the case's loads.refinement)")
    parser.add_argument("--cache", default=".femstudy-cache", help="mesh cache folder")
    parser.add_argument("--json", type=Path, help="write the case's level's verdicts here (a loads.convergence record)")
    args = parser.parse_args()
    case = load_case(args.case)
    start = time.perf_counter()
    if args.mesh_size is not None:
        case = with_overrides(case, {"mesh.size_mm": args.mesh_size}, what="--mesh-size")
    global_model = prepare(case, Path(args.cache))
    model, system = global_model.femur, global_model.system
    loading = case_loading(case, model.site.cortical_thickness_mm)
    inputs = loading.hole_inputs(case.materials.to_fe(), case.mesh.order, case.clamps.length_mm)
    fs = global_model.factorize()
    fields = fs.bc.expand(fs.factor.solve(global_model.patch.patterns[fs.bc.free]))
    print(f"{case.name}: global model {system.n_dofs:,} DOFs ({model.stats['n_tets']:,} tets), "
          f"{time.perf_counter() - start:.0f} s; cortex {model.site.cortical_thickness_mm:.2f} mm along the drill")
    base = case.loads.hole_options()
    own = base.refinement  # the level the record speaks for; a level typed to 4 digits is taken as it
    args.levels = [own if abs(level - own) <= 1e-3 else level for level in args.levels]
    if own not in args.levels:
        raise SystemExit(f"--levels must include the case's refinement {own:.4g}")
    results = []
    for level in args.levels:
        result = hole_stresses(inputs, model, system, fields, dataclasses.replace(base, refinement=level))
        results.append(result)
        stations = "; ".join(f"tip {s.tip_depth_mm:.2f} mm: {s.dofs:,} DOFs, {s.seconds:.1f} s" for s in result.stations)
        print(f"refinement {level:.4g} (wall elements {result.wall_element_mm:.3g} mm): {stations}", flush=True)
    # placement noise: the case's level once more, turned by half a hole-circle step about the axis
    step = 180.0 / Resolution(refinement=own).scaled["n_wall"]
    turned = hole_stresses(inputs, model, system, fields, dataclasses.replace(base, refinement=own, rotation_deg=step))
    reference = results[args.levels.index(own)]
    print(f"placement noise: refinement {own:.4g} turned by {step:.3g} degrees")
    h = [r.wall_element_mm for r in results]
    print("\n| measure | von Mises dynamic [MPa], wall element " + ", ".join(f"{x:.3g}" for x in h)
          + " mm | observed order | extrapolated | GCI fine | verdict |")
    print("|---|---|---|---|---|---|")
    sets = ([("distance", d, f"{d:g} mm from the hole") for d in base.distances_mm]
            + [("wall", d, f"{d:g} mm beside the wall") for d in base.distances_mm]
            + [("exclusion", r, f"beyond {r:g} mm") for r in base.exclusion_radii_mm])
    measures = []
    for kind, radius, label in sets:
        values = [r.worst(kind, radius).von_mises_MPa for r in results]
        twin = turned.worst(kind, radius).von_mises_MPa
        mid = reference.worst(kind, radius).von_mises_MPa
        noise = abs(twin - mid) / abs(mid)
        line = ", ".join(f"{v:.4g}" for v in values) + f" (turned {twin:.4g}: noise {100 * noise:.2f} %)"
        if len(values) >= 3:
            a = assess(label, h, values, formal_order=2.0, noise=noise)
            p = "—" if a.observed_order is None else f"{a.observed_order:.2f}"
            ext = "—" if a.extrapolated is None else f"{a.extrapolated:.4g}"
            gci = "—" if a.gci_fine is None else f"{100 * a.gci_fine:.2f} %"
            print(f"| {label} | {line} | {p} | {ext} | {gci} | {a.verdict}: {a.reason} |")
            verdict, gci_own = verdicts.at_level(a, reference.wall_element_mm)
            measures.append({"kind": kind, "radius_mm": radius, "values_MPa": values, "noise": noise,
                             "verdict": verdict, "gci_fine": gci_own, "ladder": a.as_dict()})
        else:
            print(f"| {label} | {line} | | | | |")
    if args.json and measures:
        conditions = verdicts.conditions(case)
        if args.mesh_size is not None:
            conditions["mesh_size_mm"] = args.mesh_size
        record = {"command": "PYTHONPATH=. python bench/hole_convergence.py " + " ".join(sys.argv[1:]),
                  "conditions": conditions, "levels": list(args.levels), "wall_element_mm": h, "measures": measures}
        write_text(args.json, json.dumps(jsonable(record), indent=1))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
