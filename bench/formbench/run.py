"""Run the form-randomised benchmark on one split and seed, or tabulate saved runs.

    PYTHONPATH=. nice python -m bench.formbench.run --split tuning --seed 1 --save results/fb-tuning-1.json
    PYTHONPATH=. nice python -m bench.formbench.run --split held_out --seed 2 --save results/fb-held-2.json
    PYTHONPATH=. python -m bench.formbench.run --table results/fb-held-1.json results/fb-held-2.json
    PYTHONPATH=. python -m bench.formbench.run --table results/fb-held-2.json --recompute-confidence

The first form writes each case (:mod:`bench.formbench.cases`) into ``--out`` (default a
temporary folder), diagnoses it through the command line (:mod:`bench.formbench.score`), prints
one line per case, then the tables; ``--save`` keeps the outcomes as JSON. ``--table`` prints
the tables and the confidence reliability table of saved outcomes taken together.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import replace
from pathlib import Path

from bench.formbench.cases import case_seeds, make_case
from bench.formbench.forms import HELD_OUT, HELD_OUT_DECOYS, TUNING, TUNING_DECOYS
from bench.formbench.score import Outcome, case_line, diagnose_case, reliability_table, summary


def _forms_note(split: str) -> str:
    forms, decoys = (TUNING, TUNING_DECOYS) if split == "tuning" else (HELD_OUT, HELD_OUT_DECOYS)
    return "; ".join(f"{m}: {', '.join(f)}" for m, f in forms.items()) + f"; decoys: {', '.join(decoys)}"


def run(split: str, seed: int, out: Path, only: list[str] | None, first: int | None) -> list[Outcome]:
    todo = [(k, s) for k, s in case_seeds(seed, split) if not only or k in only]
    if first is not None:
        seen: dict = {}
        todo = [(k, s) for k, s in todo if seen.setdefault(k, 0) < first and not seen.__setitem__(k, seen[k] + 1)]
    print(f"form-randomised benchmark, split {split}, seed {seed}: {len(todo)} cases in {out}")
    print(f"forms: {_forms_note(split)}", flush=True)
    outcomes = []
    for kind, case_seed in todo:
        case = make_case(kind, case_seed, split, out)
        outcomes.append(diagnose_case(out / f"{case.name}.truth.json"))
        print(case_line(outcomes[-1]), flush=True)
    return outcomes


def recomputed(outcome: Outcome) -> dict:
    """The outcome's named mechanisms with their confidence recomputed from the saved evidence
    (the figures are saved rounded to 4 digits: the confidence moves by less than 1e-3)."""
    from femstudy.diagnosis.confidence import Evidence, confidence

    out = {}
    for name, kept in outcome.named.items():
        e = (outcome.evidence or {}).get(name)
        out[name] = kept if not e else confidence(Evidence.from_json(e))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("tuning", "held_out"), default="tuning")
    parser.add_argument("--seed", type=int, default=1, help="benchmark seed (1 is the tuning seed)")
    parser.add_argument("--only", help="comma-separated classes to run")
    parser.add_argument("--first", type=int, help="at most this many cases per class")
    parser.add_argument("--out", type=Path, help="keep the cases and their diagnoses in this folder")
    parser.add_argument("--save", type=Path, help="write the outcomes as JSON")
    parser.add_argument("--table", nargs="+", type=Path, help="tabulate saved outcomes instead of running")
    parser.add_argument("--recompute-confidence", action="store_true",
                        help="with --table: each named mechanism's confidence recomputed from its saved evidence "
                             "under the current confidence model (for runs saved before its coefficients changed)")
    args = parser.parse_args()
    if args.table:
        outcomes = [Outcome(o["case"], o["refused"], o["named"], o["unexplained"], None, o["seconds"],
                            o.get("cpu_seconds", float("nan")), o.get("evidence"), o.get("dropped"))
                    for path in args.table for o in json.loads(path.read_text())]
        if args.recompute_confidence:
            outcomes = [replace(o, named=recomputed(o)) for o in outcomes]
        print(summary(outcomes))
        print()
        print(reliability_table(outcomes))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.out or Path(tmp)
        outcomes = run(args.split, args.seed, folder, args.only.split(",") if args.only else None, args.first)
        print()
        print(summary(outcomes))
        print()
        print(reliability_table(outcomes))
        if args.save:
            args.save.parent.mkdir(parents=True, exist_ok=True)
            args.save.write_text(json.dumps([{"case": o.case, "refused": o.refused, "named": o.named,
                                              "unexplained": o.to_json()["unexplained"], "seconds": o.seconds,
                                              "cpu_seconds": o.cpu_seconds, "evidence": o.evidence,
                                              "dropped": o.dropped}
                                             for o in outcomes], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
