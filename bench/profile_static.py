"""Where a static solve's whole process spends its time: femstudy beside DOLFINx + MUMPS.

    python bench/profile_static.py [--work results/bench-peers] [--sizes 16,8] [--repeats 3]

For each prepared benchmark folder (bench/run_all.py makes them: ``model.npz`` and
``case.npz``) it runs, alternately and each in its own process:

  femstudy   this script with ``--phases MODEL.npz``: the static solve of bench/peers/femstudy_run.py
             split into its phases (imports, reading, assembly, drill patch, clamps, K_ff, PARDISO's
             input, analysis, factorisation, solve with refinement, writing), each timed in wall
             and CPU seconds (the process's own clock, all threads)
  DOLFINx    bench/peers/dolfinx_static.py --solver mumps, whose own phase times it reports;
             its start-up (interpreter and imports) is the whole-process wall time less them

and prints a Markdown table of the medians over ``--repeats`` rounds, with the machine's load
average before and after (the machine is shared: times are noisy, ratios less so).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def phases(model_path: str, out_path: str) -> None:
    """The femstudy side: run the static solve phase by phase and print the times as JSON."""
    marks = [("start", time.perf_counter(), time.process_time())]

    def mark(name: str) -> None:
        marks.append((name, time.perf_counter(), time.process_time()))

    import numpy as np
    sys.path.insert(0, str(REPO))
    from bench.peers import femstudy_side
    from femstudy import fe
    from femstudy.atomic import atomic_path
    from femstudy.fe import linsolve, static
    mark("imports")
    model = femstudy_side.Model.load(model_path)
    mark("read model")
    system = fe.assemble(model.mesh, model.materials.to_fe(), order=2)
    mark("assembly")
    patch = fe.drill_patch(system, model.site, radius_mm=model.patch_radius_mm)
    mark("drill patch")
    bc = fe.clamp(system, model.clamps)
    mark("clamps")
    nodes = static.free_nodes(bc)
    K = static.free_block(system.K, bc.free) if nodes is None else linsolve.Restriction(system.K_blocks, nodes)
    mark("K_ff (a restriction: PARDISO's input takes its blocks)")
    factor = linsolve.factorize(K, "pardiso", precision="single")
    t = factor.timings
    mark("factorisation")
    parts = [("PARDISO input (upper 3x3 blocks)", t["input_s"]), ("analysis (ordering)", t["analysis_s"]),
             ("numeric factorisation", t["factor_s"])]
    force = model.static_thrust_N * patch.thrust + model.static_torque_Nmm * patch.torque
    u = bc.expand(factor.solve(force[bc.free]))
    mark(f"solve ({factor.refinements} refinements)")
    with atomic_path(out_path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, u=u)
    mark("write")
    factor.close()
    out = [(name, wall - marks[k][1], cpu - marks[k][2]) for k, (name, wall, cpu) in enumerate(marks[1:])]
    print(json.dumps(out + [(f"  of which {name}", seconds, float("nan")) for name, seconds in parts]))


def run(command: list[str], cwd: Path) -> tuple[float, str]:
    start = time.perf_counter()
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "2"})
    if done.returncode:
        raise SystemExit(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
    return time.perf_counter() - start, done.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=REPO / "results" / "bench-peers")
    parser.add_argument("--sizes", default="16,8")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--phases", nargs=2, metavar=("MODEL", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.phases:
        phases(*args.phases)
        return
    import numpy as np
    load_before = os.getloadavg()[0]
    print(f"started {time.strftime('%Y-%m-%d %H:%M')}, load average {load_before:.1f}")
    for size in args.sizes.split(","):
        folder = args.work / f"femur-femstudy-{float(size):g}mm"
        ours, theirs = [], []
        for _ in range(args.repeats):
            wall, out = run([sys.executable, __file__, "--phases", "model.npz", "profile-u.npz"], folder)
            ours.append((wall, json.loads(out.strip().splitlines()[-1])))
            wall, _ = run(["/usr/bin/python3", str(REPO / "bench/peers/dolfinx_static.py"), "case.npz",
                           "profile-dx.npz", "--solver", "mumps"], folder)
            with np.load(folder / "profile-dx.npz") as d:
                times = {k: float(d[k]) for k in ("t_read", "t_setup", "t_assemble", "t_factor", "t_solve")}
            theirs.append((wall, times))
        print(f"\n{size} mm: femstudy (wall / CPU s, medians of {args.repeats})\n")
        print("| phase | wall [s] | CPU [s] |\n|---|---:|---:|")
        for k, (name, _, _) in enumerate(ours[0][1]):
            cpu = statistics.median(r[1][k][2] for r in ours)
            print(f"| {name} | {statistics.median(r[1][k][1] for r in ours):.2f} | "
                  f"{'' if cpu != cpu else f'{cpu:.2f}'} |")
        inside = [sum(p[1] for p in r[1] if not p[0].startswith("  of which")) for r in ours]
        print(f"| interpreter start-up and exit | {statistics.median(w - i for (w, _), i in zip(ours, inside)):.2f} | |")
        print(f"| **whole process** | **{statistics.median(r[0] for r in ours):.2f}** | |")
        print(f"\n{size} mm: DOLFINx + MUMPS (wall s, its own phase times)\n")
        print("| phase | wall [s] |\n|---|---:|")
        for key in ("t_read", "t_setup", "t_assemble", "t_factor", "t_solve"):
            print(f"| {key[2:]} | {statistics.median(r[1][key] for r in theirs):.2f} |")
        print(f"| start-up, imports and exit | {statistics.median(w - sum(t.values()) for w, t in theirs):.2f} |")
        print(f"| **whole process** | **{statistics.median(r[0] for r in theirs):.2f}** |")
    print(f"\nload average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after")


if __name__ == "__main__":
    main()
