"""Time two commands as whole processes, alternately, and their ratio pair by pair.

    python bench/paired.py -n 6 --vs 'python bench/peers/femstudy_run.py model.npz s.npz --analysis static' \\
        -- python bench/peers/femstudy_run.py model.npz t.npz --analysis transient

A (after ``--``) and B (``--vs``, one string split as a shell would) run in turn, A B A B …,
after ``--warmup`` uncounted pairs, each measured from outside by :func:`bench.peers.measure.measure`
(wall time, CPU time, peak memory; output to a temporary log). Then A/B of wall and CPU taken
pair by pair, so that a machine whose speed drifts during the runs still gives a meaningful
ratio. Every figure is printed as min, median and max: quote the median. Standard library only,
so anyone can repeat a pairing quoted in bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import shlex
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.peers.measure import measure  # noqa: E402

FIELDS = (("wall_s", "wall s"), ("cpu_s", "cpu s"), ("tree_peak_MB", "peak MiB"))


def spread(values: list[float]) -> str:
    return f"{min(values):10.3f} {statistics.median(values):10.3f} {max(values):10.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=5, help="counted pairs (5)")
    parser.add_argument("--warmup", type=int, default=1, help="uncounted pairs first (1)")
    parser.add_argument("--vs", required=True, help="command B, the baseline, as one string")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="-- command A")
    args = parser.parse_args()
    commands = {"A": args.command[1:] if args.command[:1] == ["--"] else args.command, "B": shlex.split(args.vs)}
    if not commands["A"]:
        parser.error("give command A after --")
    runs: dict[str, list] = {"A": [], "B": []}
    with tempfile.TemporaryDirectory() as logs:
        for i in range(args.warmup + args.n):
            pair = {key: measure(command, Path(logs) / f"{key}.log") for key, command in commands.items()}
            if i >= args.warmup:
                for key, result in pair.items():
                    runs[key].append(result)
    print(f"{'':14s} {'min':>10s} {'median':>10s} {'max':>10s}   ({args.n} pairs, whole processes)")
    for key, results in runs.items():
        print(f"{key} exit {sorted({r.returncode for r in results})}")
        for field, label in FIELDS:
            print(f"{key} {label:12s} {spread([getattr(r, field) for r in results])}")
    for field, label in FIELDS[:2]:
        ratios = [getattr(x, field) / getattr(y, field) for x, y in zip(runs["A"], runs["B"])]
        print(f"A/B {label[:-2]:10s} {spread(ratios)}")


if __name__ == "__main__":
    main()
