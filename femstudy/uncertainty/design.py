"""Sample designs in the unit cube and the Sobol analysis of their outputs (SALib).

Both methods draw points u ∈ (0, 1)^D; an input's value is its distribution's quantile at u
(:meth:`femstudy.distributions.Distribution.ppf`), so the inputs are independent with the
stated marginals, and a design depends only on (method, D, samples, seed) — a run killed and
started again draws the same points.

* ``montecarlo``: ``samples`` independent uniform points (NumPy's PCG64 from ``seed``);
* ``sobol``: Saltelli's design (SALib ``sample.sobol``, scrambled Sobol' sequence, no
  second-order terms) of ``samples`` base points, N(D + 2) evaluations, analysed by SALib
  ``analyze.sobol`` (Jansen/Saltelli estimators, bootstrap confidence intervals).
"""

from __future__ import annotations

import warnings

import numpy as np

#: Bootstrap resamples and level of the Sobol indices' confidence intervals.
RESAMPLES = 1000
CONFIDENCE = 0.95


def problem(names: tuple[str, ...]) -> dict:
    """SALib's problem in the unit cube (the quantile transform is applied afterwards)."""
    return {"num_vars": len(names), "names": list(names), "bounds": [[0.0, 1.0]] * len(names)}


def unit_design(method: str, names: tuple[str, ...], samples: int, seed: int) -> np.ndarray:
    """(n, D) points in the unit cube."""
    if method == "montecarlo":
        return np.random.default_rng(seed).random((samples, len(names)))
    from SALib.sample import sobol

    with warnings.catch_warnings():  # SALib warns when N is not a power of 2; the balance it loses is stated in docs
        warnings.simplefilter("ignore")
        return sobol.sample(problem(names), samples, calc_second_order=False, scramble=True, seed=seed)


def evaluations(method: str, d: int, samples: int) -> int:
    """How many model evaluations a design of ``samples`` base points needs."""
    return samples if method == "montecarlo" else samples * (d + 2)


def sobol_indices(names: tuple[str, ...], outputs: np.ndarray, seed: int) -> dict:
    """First-order (S1) and total (ST) indices of one output and their confidence half-widths."""
    from SALib.analyze import sobol

    y = np.asarray(outputs, float)
    if not np.all(np.isfinite(y)) or np.ptp(y) == 0:
        return {}
    res = sobol.analyze(problem(names), y, calc_second_order=False, num_resamples=RESAMPLES,
                        conf_level=CONFIDENCE, seed=seed)
    return {n: {"S1": float(res["S1"][k]), "S1_conf": float(res["S1_conf"][k]), "ST": float(res["ST"][k]),
                "ST_conf": float(res["ST_conf"][k])} for k, n in enumerate(names)}


def rank_correlations(names: tuple[str, ...], unit: np.ndarray, outputs: np.ndarray) -> dict:
    """Spearman rank correlation of each input with an output (a Monte Carlo tornado)."""
    from scipy.stats import spearmanr

    y = np.asarray(outputs, float)
    ok = np.isfinite(y)
    if ok.sum() < 3 or np.ptp(y[ok]) == 0:
        return {}
    return {n: float(spearmanr(unit[ok, k], y[ok]).statistic) for k, n in enumerate(names)}
