"""Time ``femstudy diagnose`` as a user runs it — one whole process per recording, imports and
reading included — on a formbench seed's 18–22 s, 1 kHz recordings (the issue's "per 20 s /
1 kHz recording"), optionally paired with another checkout of the code.

    PYTHONPATH=. python -m bench.formbench.whole --split held_out --seed 46
    PYTHONPATH=. python -m bench.formbench.whole --split held_out --seed 46 --vs ../before

With ``--vs TREE`` each recording is diagnosed by this code (A) and by the package in TREE (B,
e.g. ``git worktree add ../before REV``), one after the other, the order swapped from one
recording to the next; per recording: wall and CPU seconds of each (the process and its fitting
workers), their ratio, and whether the named mechanisms (with their confidences) and the
unexplained kinds are the same, and whether the whole diagnosis JSON is (all but its wall time). Run it with nothing else on the machine: the figures are wall
times.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.formbench.cases import case_seeds, make_case

#: The per-recording target [s] (issue 31).
TARGET_S = 10.0
#: This checkout (A's code).
HERE = Path(__file__).resolve().parents[2]


def long_cases(split: str, seed: int, folder: Path) -> list[str]:
    """The names of the seed's 18–22 s recordings, written into ``folder`` (the others are not kept)."""
    names = []
    for kind, case_seed in case_seeds(seed, split):
        case = make_case(kind, case_seed, split, folder)
        if case.long:
            names.append(case.name)
        else:
            for path in folder.glob(f"{case.name}*"):
                path.unlink()
    return names


def diagnose(folder: Path, name: str, tree: Path, tag: str) -> tuple[float, float, tuple, dict]:
    """Wall and CPU seconds of one whole ``femstudy diagnose`` process with the package of
    ``tree``, what it named, and its JSON without the wall time. It runs in ``folder``: a working
    directory holding a package would come before PYTHONPATH."""
    out = folder / f"{name}.{tag}.json"
    before, start = os.times(), time.perf_counter()
    subprocess.run([sys.executable, "-m", "femstudy", "diagnose", f"{name}.csv", "--simulation", f"{name}-sim.csv",
                    "--json", out.name, "--quiet"],
                   cwd=folder, env={**os.environ, "PYTHONPATH": str(tree.resolve())}, check=True, capture_output=True)
    wall, after = time.perf_counter() - start, os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    result = json.loads(out.read_text())
    named = tuple((m["mechanism"], m.get("confidence")) for m in result["missing_physics"])
    result.pop("seconds", None)
    return wall, cpu, (named, tuple(u["kind"] for u in result["unexplained"])), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("tuning", "held_out"), default="held_out")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--first", type=int, help="only the first N of those recordings")
    parser.add_argument("--vs", type=Path, help="a checkout of the code to pair with (its package is put first on PYTHONPATH)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        names = long_cases(args.split, args.seed, folder)[:args.first]
        print(f"{len(names)} recordings of 18-22 s at 1 kHz, split {args.split}, seed {args.seed}", flush=True)
        walls: dict[str, list[float]] = {"A": [], "B": []}
        ratios, same, identical = [], 0, 0
        for k, name in enumerate(names):
            order = [("A", HERE), ("B", args.vs)] if args.vs else [("A", HERE)]
            runs = {tag: diagnose(folder, name, tree, tag) for tag, tree in (order if k % 2 == 0 else order[::-1])}
            line = f"{name:40s} A wall {runs['A'][0]:6.2f} s, CPU {runs['A'][1]:6.2f} s"
            walls["A"].append(runs["A"][0])
            if args.vs:
                walls["B"].append(runs["B"][0])
                ratios.append(runs["A"][0] / runs["B"][0])
                same += runs["A"][2] == runs["B"][2]
                identical += runs["A"][3] == runs["B"][3]
                line += (f"   B wall {runs['B'][0]:6.2f} s, CPU {runs['B'][1]:6.2f} s   A/B {ratios[-1]:.3f}   "
                         f"same verdict: {'yes' if runs['A'][2] == runs['B'][2] else 'NO'}, "
                         f"same JSON: {'yes' if runs['A'][3] == runs['B'][3] else 'no'}")
            print(line, flush=True)
        for tag in ("A", "B") if args.vs else ("A",):
            w = walls[tag]
            print(f"{tag}: median {statistics.median(w):.2f} s, max {max(w):.2f} s, "
                  f"{sum(x > TARGET_S for x in w)} of {len(w)} over {TARGET_S:g} s")
        if args.vs:
            print(f"A/B wall, median {statistics.median(ratios):.3f} ({min(ratios):.3f}-{max(ratios):.3f}); "
                  f"same verdict on {same} of {len(names)}, the same JSON (all but its wall time) on {identical}")


if __name__ == "__main__":
    main()
