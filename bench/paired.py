"""Time two commands as whole processes, alternately, and their ratio pair by pair.

    python bench/paired.py -n 6 --vs 'python bench/peers/femstudy_run.py model.npz s.npz --analysis static' \\
        -- python bench/peers/femstudy_run.py model.npz t.npz --analysis transient

A (after ``--``) and B (``--vs``, one string split as a shell would) run in turn, A B A B …,
after ``--warmup`` uncounted pairs; each run is one child process, its output discarded. Per
command: wall seconds (a monotonic clock around start and reaping), CPU seconds (user + system of
the child and the children it waited for, from ``os.wait4``) and peak resident memory [MiB]; then
A/B of wall and CPU taken pair by pair, so that a machine whose speed drifts during the runs
still gives a meaningful ratio. Every figure is printed as min, median and max: quote the median.
Standard library only, so anyone can repeat a pairing quoted in bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import os
import shlex
import statistics
import subprocess
import time


def run_once(command: list[str]) -> dict[str, float]:
    """One whole process: wall [s], cpu [s], peak [MiB], exit status."""
    start = time.perf_counter()
    child = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)  # reaped here: keep Popen from waiting again
    return {"wall": wall, "cpu": usage.ru_utime + usage.ru_stime, "peak": usage.ru_maxrss / 1024,
            "exit": child.returncode}


def spread(values: list[float]) -> str:
    return f"{min(values):10.3f} {statistics.median(values):10.3f} {max(values):10.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=5, help="counted pairs (5)")
    parser.add_argument("--warmup", type=int, default=1, help="uncounted pairs first (1)")
    parser.add_argument("--vs", required=True, help="command B, the baseline, as one string")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="-- command A")
    args = parser.parse_args()
    a = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not a:
        parser.error("give command A after --")
    b = shlex.split(args.vs)
    runs: dict[str, list[dict]] = {"A": [], "B": []}
    for i in range(args.warmup + args.n):
        pair = {"A": run_once(a), "B": run_once(b)}
        if i >= args.warmup:
            for key, result in pair.items():
                runs[key].append(result)
    print(f"{'':14s} {'min':>10s} {'median':>10s} {'max':>10s}   ({args.n} pairs, whole processes)")
    for key in ("A", "B"):
        exits = sorted({r["exit"] for r in runs[key]})
        print(f"{key} exit {exits}")
        for field, label in (("wall", "wall s"), ("cpu", "cpu s"), ("peak", "peak MiB")):
            print(f"{key} {label:12s} {spread([r[field] for r in runs[key]])}")
    for field in ("wall", "cpu"):
        ratios = [x[field] / y[field] for x, y in zip(runs["A"], runs["B"])]
        print(f"A/B {field:10s} {spread(ratios)}")


if __name__ == "__main__":
    main()
