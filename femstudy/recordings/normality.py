"""Normality of F_o and p across replicates (thesis §4.4, Tables 4-2 and 4-3, Appendix B).

Three checks:

- **Median-rank probability plot** (§4.4.3, Figs 4-13/4-14): the i-th smallest of n values is
  plotted against the standard normal quantile of its median rank (i − 0.3)/(n + 0.4)
  (Benard's approximation); a straight line means normal. The correlation r of that line is
  reported (Filliben's probability-plot correlation).
- **Chi-square** exactly as the thesis did it (§4.4.4): standardise with the sample mean and
  the sample standard deviation (n − 1; Table B-2's "Sigma" 3.5925 is that one), count the
  values in ten bins of width 0.5 from −2 to 2 plus the two tails (a value on a bin edge goes
  to the upper bin), take each bin's normal probability **rounded to three decimals**
  (0.023, 0.044, 0.092, 0.150, 0.191 — the printed column), expected = n × that probability,
  and sum (O − E)²/E. Degrees of freedom 10 − 1 − 2 = 7 (Eq A.4), critical value
  χ²₀.₉₅(7) = 14.07 ("14.1"). On Appendix B's thirty trials this reproduces every entry of
  Tables 4-2 and 4-3, and their sums 8.3297 and 8.5606.
- **Shapiro–Wilk** (``scipy.stats.shapiro``), the more powerful test for small samples.

With only 10 bins and expected counts below 5 in six of them, the chi-square test is weak
at n = 30 (the thesis's own rule of thumb), and meaningless for ten replicates; the
calibration pools values standardised within each condition before applying it.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from scipy import stats

from femstudy.errors import UserError, require

BIN_EDGES = (-np.inf, -2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0, np.inf)
CONFIDENCE = 0.95


def median_ranks(n: int) -> np.ndarray:
    """Benard's median ranks (i − 0.3)/(n + 0.4), i = 1..n."""
    return (np.arange(1, n + 1) - 0.3) / (n + 0.4)


@dataclass(frozen=True)
class ProbabilityPlot:
    """Sorted values against normal quantiles of their median ranks, and the fitted line."""

    values: np.ndarray
    quantiles: np.ndarray
    slope: float
    intercept: float
    r: float


def probability_plot(values) -> ProbabilityPlot:
    x = np.sort(np.asarray(values, float))
    q = stats.norm.ppf(median_ranks(x.size))
    slope, intercept = np.polyfit(q, x, 1)
    return ProbabilityPlot(x, q, float(slope), float(intercept), float(np.corrcoef(q, x)[0, 1]))


@dataclass(frozen=True)
class ChiSquareTable:
    """One row per bin (label, observed, probability, expected, O − E, chi-square) and totals."""

    rows: list[tuple[str, int, float, float, float, float]]
    total: int
    statistic: float
    dof: int
    critical: float

    @property
    def normal(self) -> bool:
        """The null hypothesis (normal) is kept at 95 % confidence."""
        return self.statistic < self.critical


def _bin_label(lo: float, hi: float) -> str:
    if np.isinf(lo):
        return f"< {hi:.1f}"
    if np.isinf(hi):
        return f"> {lo:.1f}"
    return f"{lo:.1f} to {hi:.1f}"


def chi_square_table(values) -> ChiSquareTable:
    """The thesis's chi-square test for normality (see the module docstring)."""
    x = np.asarray(values, float)
    require(x.size >= 3 and np.std(x) > 0, "a normality test needs at least three values that differ")
    z = (x - x.mean()) / x.std(ddof=1)
    rows, statistic = [], 0.0
    for lo, hi in zip(BIN_EDGES[:-1], BIN_EDGES[1:]):
        observed = int(np.count_nonzero((z >= lo) & (z < hi)))
        probability = round(float(stats.norm.cdf(hi) - stats.norm.cdf(lo)), 3)
        expected = x.size * probability
        chi = (observed - expected) ** 2 / expected
        statistic += chi
        rows.append((_bin_label(lo, hi), observed, probability, expected, observed - expected, chi))
    dof = len(rows) - 1 - 2
    return ChiSquareTable(rows, x.size, statistic, dof, float(stats.chi2.ppf(CONFIDENCE, dof)))


def format_chi_square(table: ChiSquareTable, title: str) -> str:
    """The table laid out like Tables 4-2/4-3."""
    lines = [title, f"  {'bin':<12} {'observed':>8} {'normal p':>9} {'expected':>9} {'O - E':>7} {'chi-square':>11}"]
    for label, o, p, e, d, c in table.rows:
        lines.append(f"  {label:<12} {o:>8d} {p:>9.3f} {e:>9.2f} {d:>7.2f} {c:>11.4f}")
    verdict = "normal" if table.normal else "NOT normal"
    lines.append(f"  {'total':<12} {table.total:>8d} {'':>9} {'':>9} {'':>7} {table.statistic:>11.4f}")
    lines.append(f"  sum {table.statistic:.4f} {'<' if table.normal else '>='} {table.critical:.1f} "
                 f"(chi-square, v = {table.dof}, 95 %): {verdict}")
    return "\n".join(lines)


@dataclass(frozen=True)
class NormalityResult:
    """All three checks for one quantity."""

    name: str
    n: int
    mean: float
    sd: float
    chi_square: ChiSquareTable | None
    shapiro_w: float
    shapiro_p: float
    plot: ProbabilityPlot


def normality(name: str, values) -> NormalityResult:
    """Chi-square (when n ≥ 30, the thesis's minimum), Shapiro–Wilk and the probability plot."""
    x = np.asarray(values, float)
    require(x.size >= 3, f"normality of {name} needs at least three values, got {x.size}")
    w, p = stats.shapiro(x)
    return NormalityResult(name, x.size, float(x.mean()), float(x.std(ddof=1)),
                           chi_square_table(x) if x.size >= 30 else None, float(w), float(p),
                           probability_plot(x))


def format_normality(result: NormalityResult, title: str | None = None) -> str:
    lines = []
    if result.chi_square is not None:
        lines += [format_chi_square(result.chi_square, title or f"Chi-square test for normality: {result.name}"), ""]
    else:
        lines.append(f"{title or result.name}: n = {result.n} < 30, chi-square not applied")
    verdict = "consistent with normal" if result.shapiro_p > 1 - CONFIDENCE else "NOT normal"
    mean = 0.0 if abs(result.mean) < 1e-9 * max(result.sd, 1e-300) else result.mean
    lines.append(f"  {result.name}: mean {mean:.6g}, sd {result.sd:.4g}, n = {result.n}; "
                 f"Shapiro-Wilk W = {result.shapiro_w:.4f}, p = {result.shapiro_p:.3f} ({verdict} at 5 %); "
                 f"median-rank plot r = {result.plot.r:.4f}")
    return "\n".join(lines)


def appendix_b() -> tuple[np.ndarray, np.ndarray]:
    """(p, F_o [N]) of the thirty bovine trials of Table B-1 (f = 1.5 mm/s, N = 1500 rpm)."""
    text = resources.files("femstudy.drilling").joinpath("data", "appendix_b_normality_trials.csv").read_text()
    rows = list(csv.DictReader(line for line in text.splitlines() if line and not line.startswith("#")))
    return (np.array([float(r["growth_exponent_p"]) for r in rows]),
            np.array([float(r["initial_force_N"]) for r in rows]))


#: What a trial's fit can be: F_o a drilling force (0, 10 kN] (femstudy.recordings.ranges),
#: p finite and at most 100 per mm in size (the thesis's thirty trials: 0.29-0.65); a trials
#: file is a short table (at most 16 MB).
MAX_INITIAL_FORCE_N, MAX_GROWTH_EXPONENT, MAX_TRIALS_BYTES = 1e4, 100.0, 16 << 20


def read_trials(path) -> tuple[list[float], list[float]]:
    """(p, F_o) from a CSV; rows whose 'role' is outlier or validation are skipped. Values
    must be finite and in range (:data:`MAX_INITIAL_FORCE_N`, :data:`MAX_GROWTH_EXPONENT`)."""
    import csv
    import math

    path = Path(path)
    require(path.is_file(), f"{path} is not a file" if path.exists() else f"{path} does not exist")
    require(path.stat().st_size <= MAX_TRIALS_BYTES, f"{path} is {path.stat().st_size:,} bytes; a table of trials "
                                                     f"is at most {MAX_TRIALS_BYTES >> 20} MB")
    try:
        lines = [line for line in path.read_text(encoding="utf-8").splitlines() if line and not line.startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read {path}: {getattr(exc, 'strerror', None) or exc}") from None
    rows = list(csv.DictReader(lines))
    require(rows and {"initial_force_N", "growth_exponent_p"} <= set(rows[0]),
            f"{path} needs columns initial_force_N and growth_exponent_p")
    rows = [r for r in rows if r.get("role", "calibration") in ("calibration", "held out")]
    try:
        p, force = [float(r["growth_exponent_p"]) for r in rows], [float(r["initial_force_N"]) for r in rows]
    except (ValueError, TypeError) as exc:
        raise UserError(f"{path}: {exc}") from None
    for k, (pk, fk) in enumerate(zip(p, force)):
        require(math.isfinite(fk) and 0 < fk <= MAX_INITIAL_FORCE_N,
                f"{path}, row {k + 2}: initial_force_N = {fk:g} is not a drilling force (0-{MAX_INITIAL_FORCE_N:g} N)")
        require(math.isfinite(pk) and abs(pk) <= MAX_GROWTH_EXPONENT,
                f"{path}, row {k + 2}: growth_exponent_p = {pk:g} is not a growth exponent (within "
                f"±{MAX_GROWTH_EXPONENT:g} per mm)")
    return p, force


def normality_study(trials=None, plot_path=None) -> str:
    """Chi-square (Tables 4-2/4-3 method), Shapiro–Wilk and median-rank plots of F_o and p.

    Parameters
    ----------
    trials : path-like, optional
        CSV with columns initial_force_N and growth_exponent_p (e.g. runs.csv of a
        calibration); default the thirty trials of Appendix B (Table B-1).
    plot_path : path-like, optional
        Write the probability plots (PNG/PDF/SVG).

    Returns
    -------
    str
        The tables, as ``femstudy normality`` prints them.
    """
    require(plot_path is None or str(plot_path).lower().endswith((".png", ".pdf", ".svg")),
            f"--plot must end in .png, .pdf or .svg, got '{plot_path}'")
    if trials is None:
        p, F = appendix_b()
        source = "thesis Appendix B, Table B-1 (30 bovine trials, f = 1.5 mm/s, N = 1500 rpm)"
        titles = ("Table 4-2: chi-square test for normality, initial cutting force F_o",
                  "Table 4-3: chi-square test for normality, growth exponent p")
    else:
        p, F = read_trials(Path(trials))
        source = str(trials)
        titles = ("Chi-square test for normality, initial cutting force F_o",
                  "Chi-square test for normality, growth exponent p")
    results = {"initial cutting force F_o [N]": normality("F_o [N]", F), "growth exponent p [-]": normality("p", p)}
    if plot_path:
        from femstudy.recordings.figures import plot_normality

        plot_normality(plot_path, results)
    return "\n".join([f"normality of {len(F)} trials from {source}\n"]
                     + [format_normality(res, title) + "\n" for title, res in zip(titles, results.values())]).rstrip()
