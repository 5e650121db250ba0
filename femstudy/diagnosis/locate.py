"""Where recording and simulation differ beyond the noise: intervals per channel.

On the smoothed residual r_j (recording − aligned simulation) with standard error σ_j, the
instants with |r_j/σ_j| above the family-wise threshold k = Φ⁻¹(1 − α/2n_eff), α = 0.001,
are flagged (with n_eff a few hundred, k ≈ 4.5); flagged instants closer than ``MERGE_GAP``
decimation steps form one interval. Its significance is −log10 p of the χ² test of all its
instants, Σ z_j² on n_eff-scaled degrees of freedom (the residual there is not noise with
probability 1 − p).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

ALPHA = 0.001
MERGE_GAP = 2


def _log_sf(chi2: float, dof: float) -> float:
    """ln P(χ²_dof > chi2); past the floating-point range of the exact tail, the Wilson–Hilferty
    normal approximation (relative error of the logarithm well under 1 % there)."""
    exact = float(stats.chi2.logsf(chi2, dof))
    if np.isfinite(exact):
        return exact
    z = ((chi2 / dof) ** (1 / 3) - (1 - 2 / (9 * dof))) / np.sqrt(2 / (9 * dof))
    return float(stats.norm.logsf(z))


def mismatch_intervals(t: np.ndarray, z: np.ndarray, n_eff_factor: float, channel: str, chi2_of=None) -> list[dict]:
    """Intervals [start_s, end_s] where the standardised residual ``z`` is beyond noise.

    ``chi2_of(lo, hi)``, when given, is the χ² of instants lo..hi under the noise model
    (whitened, so the interval's correlations are counted); by default Σ z² scaled by
    ``n_eff_factor``."""
    n_eff = max(z.size * n_eff_factor, 1.0)
    k = float(stats.norm.isf(ALPHA / (2 * n_eff)))
    flagged = np.flatnonzero(np.abs(z) > k)
    if flagged.size == 0:
        return []
    step = float(np.median(np.diff(t)))
    groups = np.split(flagged, np.flatnonzero(np.diff(flagged) > MERGE_GAP) + 1)
    out = []
    for g in groups:
        lo, hi = g[0], g[-1]
        dof = (hi - lo + 1) * n_eff_factor
        chi2 = chi2_of(lo, hi) if chi2_of else float(np.sum(z[lo:hi + 1] ** 2)) * n_eff_factor
        significance = -_log_sf(chi2, dof) / np.log(10)
        out.append({"start_s": float(max(t[lo] - step / 2, t[0])), "end_s": float(min(t[hi] + step / 2, t[-1])),
                    "channel": channel, "significance": round(significance, 2),
                    "max_abs_z": round(float(np.max(np.abs(z[lo:hi + 1]))), 2)})
    return out
