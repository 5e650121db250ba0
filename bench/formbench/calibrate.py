"""Fit the confidence model's coefficients on saved benchmark runs (tuning split only).

    PYTHONPATH=. python -m bench.formbench.calibrate results/fb-tuning-1.json [more.json ...]

Every mechanism a run judged is one example: its evidence (the figures
:class:`femstudy.diagnosis.confidence.Evidence` holds: the JSON's ``evidence`` of a named one,
``selection.dropped_by_confidence`` of one the naming bar dropped) and whether the truth has it.
The dropped count too: the model is applied to every mechanism the verdict proposes, and fitted
on the named alone it would never see the cases that fall below the bar. The
coefficients of :data:`femstudy.diagnosis.confidence.COEFFICIENTS` are the penalised (ridge,
:data:`RIDGE` on all but the intercept) maximum-likelihood logistic fit; the script prints them,
the in-sample reliability table and refuses files of the held-out split, whose forms must stay
unseen by the calibration.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy import optimize

from femstudy.diagnosis.confidence import COEFFICIENTS, Evidence

RIDGE = 1.0
FOUR = ("chip_clogging", "feed_pulsation", "sensor_drift", "thermal_softening")


def examples(paths: list[Path]) -> tuple[np.ndarray, np.ndarray]:
    """Features and outcomes (1: the mechanism is in the truth) of every judged mechanism."""
    X, y = [], []
    for path in paths:
        for o in json.loads(path.read_text()):
            if o["case"]["split"] != "tuning":
                sys.exit(f"{path}: {o['case']['name']} is of the {o['case']['split']} split; calibrate on tuning runs only")
            judged = [(m, e) for m, e in (o.get("evidence") or {}).items() if m in FOUR and e]
            judged += [(m, d["evidence"]) for m, d in (o.get("dropped") or {}).items()]
            for m, e in judged:
                X.append(Evidence.from_json(e).features())
                y.append(1.0 if m in o["case"]["truth"] else 0.0)
    return np.array(X), np.array(y)


def fit(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    def loss(w):
        z = X @ w
        return float(np.sum(np.logaddexp(0.0, z) - y * z) + 0.5 * RIDGE * np.sum(w[1:] ** 2))

    def grad(w):
        p = 1.0 / (1.0 + np.exp(-(X @ w)))
        g = X.T @ (p - y)
        g[1:] += RIDGE * w[1:]
        return g

    return optimize.minimize(loss, np.array(COEFFICIENTS, float), jac=grad, method="BFGS").x


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    args = parser.parse_args()
    X, y = examples(args.runs)
    w = fit(X, y)
    print(f"{len(y)} judged mechanisms, {int(y.sum())} right")
    print("COEFFICIENTS = (" + ", ".join(f"{v:.3g}" for v in w) + ")")
    p = 1.0 / (1.0 + np.exp(-(X @ w)))
    for lo, hi in ((0.0, 0.5), (0.5, 0.7), (0.7, 0.8), (0.8, 0.9), (0.9, 0.95), (0.95, 1.0001)):
        inside = (p >= lo) & (p < hi)
        if inside.any():
            print(f"  {lo:.2f}-{min(hi, 1.0):.2f}: {int(inside.sum()):4d} judged, {y[inside].mean():.3f} right, "
                  f"mean confidence {p[inside].mean():.3f}")
    print(f"log loss {float(np.mean(np.logaddexp(0.0, X @ w) - y * (X @ w))):.4f} "
          f"(the constant model: {-(y.mean() * math.log(y.mean()) + (1 - y.mean()) * math.log(1 - y.mean())):.4f})"
          if 0 < y.mean() < 1 else "")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
