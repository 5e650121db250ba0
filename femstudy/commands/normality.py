"""``femstudy normality``: the thesis's normality tests (Tables 4-2/4-3) on F_o and p."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.errors import UserError, require


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("normality", help="normality of F_o and p: Tables 4-2/4-3, Shapiro-Wilk, median ranks",
                       description="Chi-square tests exactly as thesis Tables 4-2 and 4-3, Shapiro-Wilk and "
                                   "median-rank probability plots of the initial cutting force F_o and the "
                                   "growth exponent p. Without a file: the thirty trials of Appendix B.")
    p.add_argument("trials", nargs="?", type=Path,
                   help="CSV with columns initial_force_N and growth_exponent_p (e.g. runs.csv of "
                        "femstudy calibrate; only calibration and held-out runs are used)")
    p.add_argument("--plot", type=Path, help="write the probability plots (PNG/PDF/SVG)")
    p.set_defaults(run=run)


def read_trials(path: Path) -> tuple[list[float], list[float]]:
    """(p, F_o) from a CSV; rows whose 'role' is outlier or validation are skipped."""
    import csv

    try:
        lines = [line for line in path.read_text(encoding="utf-8").splitlines() if line and not line.startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read {path}: {getattr(exc, 'strerror', None) or exc}") from None
    rows = list(csv.DictReader(lines))
    require(rows and {"initial_force_N", "growth_exponent_p"} <= set(rows[0]),
            f"{path} needs columns initial_force_N and growth_exponent_p")
    rows = [r for r in rows if r.get("role", "calibration") in ("calibration", "held out")]
    try:
        return [float(r["growth_exponent_p"]) for r in rows], [float(r["initial_force_N"]) for r in rows]
    except ValueError as exc:
        raise UserError(f"{path}: {exc}") from None


def run(args: argparse.Namespace) -> int:
    from femstudy.recordings.normality import appendix_b, format_normality, normality

    require(args.plot is None or args.plot.suffix.lower() in (".png", ".pdf", ".svg"),
            f"--plot must end in .png, .pdf or .svg, got '{args.plot}'")
    if args.trials is None:
        p, F = appendix_b()
        source = "thesis Appendix B, Table B-1 (30 bovine trials, f = 1.5 mm/s, N = 1500 rpm)"
        titles = ("Table 4-2: chi-square test for normality, initial cutting force F_o",
                  "Table 4-3: chi-square test for normality, growth exponent p")
    else:
        p, F = read_trials(args.trials)
        source = str(args.trials)
        titles = ("Chi-square test for normality, initial cutting force F_o",
                  "Chi-square test for normality, growth exponent p")
    results = {"initial cutting force F_o [N]": normality("F_o [N]", F), "growth exponent p [-]": normality("p", p)}
    print(f"normality of {len(F)} trials from {source}\n")
    for title, res in zip(titles, results.values()):
        print(format_normality(res, title) + "\n")
    if args.plot:
        from femstudy.recordings.figures import plot_normality

        plot_normality(args.plot, results)
        print(f"wrote {args.plot}")
    return 0
