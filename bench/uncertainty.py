"""Measurements of ``femstudy uncertainty`` (docs/uncertainty.md; results in bench/RESULTS.md).

    python bench/uncertainty.py load             # 10,000 load samples against one cached study
    python bench/uncertainty.py sobol            # Sobol, 9 inputs, 512 base samples, 2 workers
    python bench/uncertainty.py cohort           # >= 5 femurs on a 2-worker LocalCluster, killed and resumed

``cohort`` runs the cohort once uninterrupted, then again into a fresh folder, killing that run
(SIGKILL of the whole process group, LocalCluster included) once ``--kill-after`` points are
stored, starts it again and compares every sample of the two CSVs. The real femurs are read
from ../femurs (msk-STAPLE, bench/staple_femurs.py) and ../shared (TLEM 2); cases whose femur
is absent are left out, saying so.
"""

from __future__ import annotations

import argparse
import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
COHORT = [REPO / "cases" / "middiaphysis.toml", *sorted((REPO / "bench" / "cases" / "cohort").glob("*.toml"))]


def femstudy(*args: str) -> list[str]:
    return [sys.executable, "-m", "femstudy", *args]


def timed(command: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, cwd=REPO, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def load(args) -> None:
    study = timed(femstudy("run", "cases/middiaphysis.toml", "--out", "results/bench-unc-study", "--quiet"))
    unc = timed(femstudy("uncertainty", "cases/middiaphysis.toml", "--inputs", "load", "--samples", "10000",
                         "--hole-samples", "0", "--workers", "1", "--out", "results/bench-unc-load", "--quiet"))
    import json

    doc = json.loads((REPO / "results/bench-unc-load/uncertainty.json").read_text())
    print(f"cached study {study:.1f} s; uncertainty, 10,000 load samples {unc:.1f} s "
          f"(of which the samples {doc['femurs'][0]['seconds']['samples_s']:.1f} s, preparing the femur "
          f"{doc['femurs'][0]['seconds']['prepare_s']:.1f} s); beyond the study {unc - study:+.1f} s")


def sobol(args) -> None:
    seconds = timed(femstudy("uncertainty", "cases/middiaphysis.toml", "--method", "sobol", "--samples",
                             str(args.samples), "--inputs", "all", "--hole-samples", "0", "--workers", "2",
                             "--out", "results/bench-unc-sobol", "--quiet"))
    import json

    doc = json.loads((REPO / "results/bench-unc-sobol/uncertainty.json").read_text())
    f = doc["femurs"][0]
    print(f"Sobol, {len(f['inputs'])} inputs, {args.samples} base samples ({f['evaluations']} evaluations): "
          f"{seconds:.0f} s; reduced basis {f['reduced_basis']}")
    for name, s in sorted(f["sensitivity"]["max_deflection_mm"].items(), key=lambda kv: -kv[1]["ST"]):
        print(f"  {name:28s} S1 {s['S1']:.3f} +- {s['S1_conf']:.3f}   ST {s['ST']:.3f} +- {s['ST_conf']:.3f}")


def _cases() -> list[str]:
    from femstudy.casefile import load_case

    found = []
    for path in COHORT:
        surface = load_case(path).surface_path()
        if surface is None or surface.is_file():
            found.append(str(path.relative_to(REPO)))
        else:
            print(f"left out {path.name}: {surface} is absent")
    return found


def _rows(folder: Path) -> list[dict]:
    with open(folder / "uncertainty.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def cohort(args) -> None:
    cases = _cases()
    common = ["uncertainty", *cases, "--samples", str(args.samples), "--hole-samples", str(args.hole_samples),
              "--inputs", args.inputs, "--workers", "2", "--quiet"]
    whole = REPO / "results" / "bench-unc-cohort-whole"
    broken = REPO / "results" / "bench-unc-cohort-resumed"
    for folder in (whole, broken):
        subprocess.run(["rm", "-rf", str(folder)], check=True)
    seconds = timed(femstudy(*common, "--out", str(whole)))
    print(f"uninterrupted: {len(cases)} cases in {seconds:.0f} s", flush=True)
    run = subprocess.Popen(femstudy(*common, "--out", str(broken)), cwd=REPO, start_new_session=True,
                           stdout=subprocess.DEVNULL)
    points = broken / "points"
    while run.poll() is None and len(list(points.glob("*.json"))) < args.kill_after:
        time.sleep(0.5)
    stored = len(list(points.glob("*.json")))
    os.killpg(run.pid, signal.SIGKILL)
    run.wait()
    print(f"killed with {stored} points stored", flush=True)
    seconds = timed(femstudy(*common, "--out", str(broken)))
    print(f"resumed: {seconds:.0f} s")
    a, b = _rows(whole), _rows(broken)
    assert len(a) == len(b), (len(a), len(b))
    differ = [(i, k) for i, (x, y) in enumerate(zip(a, b)) for k in x if x[k] != y[k]]
    worst = 0.0
    for i, k in differ:
        x, y = float(a[i][k]), float(b[i][k])  # text columns (case, margin basis) never differ here
        worst = max(worst, abs(x - y) / max(abs(x), abs(y), 1e-300))
    print(f"{len(a)} samples x {len(a[0])} columns compared: {len(differ)} values differ, largest relative "
          f"difference {worst:.2g}" + (" (kept solutions serving a repeated hole model differ by round-off)"
                                       if differ else " (identical CSVs)"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(required=True)
    sub.add_parser("load").set_defaults(run=load)
    p = sub.add_parser("sobol")
    p.add_argument("--samples", type=int, default=512)
    p.set_defaults(run=sobol)
    p = sub.add_parser("cohort")
    p.add_argument("--samples", type=int, default=256)
    p.add_argument("--hole-samples", type=int, default=0)
    p.add_argument("--inputs", default="load")
    p.add_argument("--kill-after", type=int, default=4, help="stored points before the kill")
    p.set_defaults(run=cohort)
    args = parser.parse_args()
    args.run(args)


if __name__ == "__main__":
    main()
