"""Wall time of ``femstudy diagnose`` with its fits spread over the cores against all in one
process (``--workers 1``), on formbench cases, alternating, in one process already warm.

    PYTHONPATH=. python -m bench.formbench.workers --rounds 2 tuning:pulsation:501002 \\
        held_out:decoy:second_cortex:369002

A case is ``SPLIT:KIND:SEED`` with formbench's kinds (``decoy:second_cortex`` for a decoy). Per
case: the median wall and CPU time (the process and its workers) of each way, their ratio, and
whether every run named the same mechanisms.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

from bench.formbench.cases import make_case
from bench.formbench.score import diagnose_case

WAYS = {"spread": None, "one process": 1}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="+", metavar="SPLIT:KIND:SEED")
    parser.add_argument("--rounds", type=int, default=2, help="runs of each way per case (2)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        truths = []
        for spec in args.cases:
            split, *kind, seed = spec.split(":")
            case = make_case(":".join(kind), int(seed), split, Path(tmp))
            truths.append(Path(tmp) / f"{case.name}.truth.json")
        diagnose_case(truths[0])   # imports and unit registry, as in a benchmark's later cases
        for truth in truths:
            runs: dict[str, list] = {way: [] for way in WAYS}
            for r in range(args.rounds):
                for way in (list(WAYS) if r % 2 == 0 else list(WAYS)[::-1]):
                    runs[way].append(diagnose_case(truth, WAYS[way]))
            wall = {way: statistics.median(o.seconds for o in runs[way]) for way in WAYS}
            cpu = {way: statistics.median(o.cpu_seconds for o in runs[way]) for way in WAYS}
            same = len({frozenset(o.named) for way in WAYS for o in runs[way]}) == 1
            print(f"{truth.name.removesuffix('.truth.json'):40s} "
                  + "  ".join(f"{way}: wall {wall[way]:5.2f} s, CPU {cpu[way]:5.2f} s" for way in WAYS)
                  + f"  ratio {wall['spread'] / wall['one process']:.3f}  same names: {'yes' if same else 'NO'}",
                  flush=True)


if __name__ == "__main__":
    main()
