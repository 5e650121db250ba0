"""Diagnose a drilling recording against a simulated trace from a script.

    femstudy synth --out rec.csv --seed 3                 # a recording: clogging, pulsation, drift
    femstudy synth --out sim.csv --model allotta --clean  # a simulation without them
    python docs/examples/diagnose_recording.py rec.csv sim.csv [OUT.json]

Uses only the public API (``import femstudy``); the tests run it on such a pair.
"""

import sys
from pathlib import Path

import femstudy


def main(recording: Path, simulation: Path, json_path: Path | None = None):
    d = femstudy.diagnose(recording, simulation)  # a femstudy.Diagnosis
    for m in d.mechanisms:
        print(f"missing: {m.mechanism} (confidence {m.confidence:.2f}) {m.reading.parameters}")
    for u in d.unexplained:
        print(f"unexplained, {u.channel} {u.start_s:.2f}-{u.end_s:.2f} s: {u.description}")
    fit = d.to_json()["fit"]
    print(f"thrust R2 {fit['baseline']['r2']:.3f} -> {fit['improved']['r2']:.4f} in sample, "
          f"{fit['baseline']['r2_heldout']:.3f} -> {fit['improved']['r2_heldout']:.4f} held out")
    d.write(json_path=json_path)
    return d


if __name__ == "__main__":
    main(*[Path(a) for a in sys.argv[1:4]])
