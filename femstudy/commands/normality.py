"""``femstudy normality``: the thesis's normality tests (Tables 4-2/4-3) on F_o and p."""

from __future__ import annotations

import argparse
from pathlib import Path


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


def run(args: argparse.Namespace) -> int:
    from femstudy.recordings.normality import normality_study
    from femstudy.writable import check_output_file

    if args.plot is not None:
        check_output_file(args.plot, "the figure", inputs=[args.trials] if args.trials else [])
    text = normality_study(args.trials, plot_path=args.plot)
    print(text)
    if args.plot:
        print(f"wrote {args.plot}")
    return 0
