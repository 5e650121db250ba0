"""``femstudy uncertainty``: distributions and Sobol indices of a study's outputs, for one or more cases."""

from __future__ import annotations

import argparse
from pathlib import Path


def _names(text: str) -> tuple[str, ...]:
    from femstudy.distributions import INPUTS, LOAD_INPUTS, STIFFNESS_INPUTS

    groups = {"load": LOAD_INPUTS, "stiffness": STIFFNESS_INPUTS, "all": tuple(INPUTS)}
    out = []
    for name in (x.strip() for x in text.split(",") if x.strip()):
        if name in groups:
            out += [n for n in groups[name] if n not in out]
        elif name in INPUTS:
            out.append(name)
        else:
            raise argparse.ArgumentTypeError(f"unknown input '{name}': choose from load, stiffness, all, "
                                             + ", ".join(INPUTS))
    if not out:
        raise argparse.ArgumentTypeError("name at least one input")
    return tuple(out)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("uncertainty", help="distributions and Sobol indices of the outputs, one or more cases",
                       description="Sample the uncertain inputs of each case (its [uncertainty] table, with cited "
                                   "defaults: friction, cutting force, feed, speed, cortex, moduli, clamped length) "
                                   "and write the distributions of the deflections, near-hole stresses and the "
                                   "governing margin, Sobol indices (--method sobol), figures, uncertainty.json, "
                                   "uncertainty.csv and report.md. Several cases make a cohort, summarised per "
                                   "case and pooled. A run killed part-way resumes where it stopped (docs/uncertainty.md).")
    p.add_argument("cases", type=Path, nargs="+", metavar="CASE.toml")
    p.add_argument("--samples", type=int, help="samples (montecarlo) or base samples, a power of 2 (sobol); "
                                               "default: the case's uncertainty.samples")
    p.add_argument("--method", choices=("montecarlo", "sobol"), help="default: the case's uncertainty.method")
    p.add_argument("--inputs", type=_names, metavar="NAME,...",
                   help="the inputs that vary: names, or the groups load, stiffness, all (default: the case's)")
    p.add_argument("--hole-samples", type=int, metavar="N", help="samples that also run the hole models "
                                                                 "(default: the case's uncertainty.hole_samples)")
    p.add_argument("--seed", type=int, help="seed of the design (default: the case's)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=2,
                       help="Dask LocalCluster worker processes (2); 1 runs in this process without Dask")
    where.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--memory-limit-gb", type=float, metavar="GB",
                   help="memory limit of each LocalCluster worker (default: 80 %% of the available memory, shared)")
    p.add_argument("--out", type=Path, help="results folder (default results/uncertainty-<first case name>)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from femstudy.errors import UserError
    from femstudy.uncertainty.run import run_uncertainty

    if args.samples is not None and args.samples < 2:
        raise UserError(f"--samples must be at least 2, got {args.samples}")
    if args.hole_samples is not None and args.hole_samples < 0:
        raise UserError(f"--hole-samples must be 0 or more, got {args.hole_samples}")
    s = args.settings
    result = run_uncertainty(args.cases, args.out, samples=args.samples, method=args.method, inputs=args.inputs,
                         hole_samples=args.hole_samples, seed=args.seed, workers=args.workers,
                         scheduler=args.scheduler,
                         memory_limit=None if args.memory_limit_gb is None else args.memory_limit_gb * 1e9,
                         cache_dir=s.cache_dir, solver=s.solver, bones_dir=s.bones_dir)
    for f in result.femurs:
        summary = f.summary()
        for name in ("max_deflection_mm", "drill_point_deflection_mm", "hole_von_mises_MPa", "governing_margin"):
            st = summary.get(name)
            if st:
                print(f"{f.name}: {name} mean {st['mean']:.4g}, SD {st['sd']:.3g}, 5/50/95 % "
                      f"{st['p5']:.4g} / {st['p50']:.4g} / {st['p95']:.4g} (n = {st['n']})")
        p = summary.get("P(governing_margin < 1)")
        if p:
            print(f"{f.name}: P(governing margin < 1) = {p['probability']:.3g} "
                  f"(95 % {p['wilson95'][0]:.3g}-{p['wilson95'][1]:.3g}, n = {p['n']})")
    print(f"{len(result.femurs)} case(s), {result.execution['wall_s']:.1f} s -> {result.out_dir}")
    return 0
