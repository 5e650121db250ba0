"""``femstudy sweep``: mesh-convergence and parameter sweeps, locally or on a Dask cluster."""

from __future__ import annotations

import argparse
from pathlib import Path

from femstudy.errors import UserError, require


def _numbers(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated sizes in mm, got '{text}'") from None


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="mesh-convergence or parameter sweep",
                       description="With a case file and --sizes: a mesh-convergence study (observed order, "
                                   "Richardson extrapolation, GCI, recommended size). With a sweep file "
                                   "(case = ..., [grid] / [[point]]): the study at every parameter point.")
    p.add_argument("file", type=Path, metavar="CASE_OR_SWEEP.toml")
    p.add_argument("--sizes", type=_numbers, metavar="MM,MM,...", help="global element sizes [mm]")
    p.add_argument("--order", choices=("1", "2", "both"), default="2", help="element order (2)")
    p.add_argument("--refine", choices=("site", "uniform", "both"), default="site",
                   help="local refinement at the drill site (site)")
    p.add_argument("--target", type=float, default=0.02, help="target relative error on max deflection (0.02)")
    p.add_argument("--workers", type=int, default=1, help="local worker processes (1)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--out", type=Path, help="sweep folder (default results/sweep-<name>)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import tomllib

    require(args.file.is_file(), f"{args.file} does not exist")
    require(args.workers >= 1, f"--workers must be at least 1, got {args.workers}")
    require(0 < args.target < 1, f"--target is a relative error in (0, 1), got {args.target}")
    try:
        is_sweep_file = "case" in tomllib.loads(args.file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read {args.file}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{args.file}: TOML syntax error: {exc}") from None
    if is_sweep_file:
        require(args.sizes is None, "--sizes belongs to a mesh sweep of a case file, not to a sweep file")
        return _parameter_sweep(args)
    require(args.sizes is not None, "a mesh-convergence sweep needs --sizes, e.g. --sizes 32,16,8,6,4")
    return _mesh_sweep(args)


def _execute(args, points, case, case_path, folder, runs=None):
    import hashlib

    from femstudy.console import Console
    from femstudy.sweep import points as point_functions
    from femstudy.sweep.execute import execute

    from femstudy.meshing.cache import cache_root

    console = Console(quiet=args.quiet)
    text = case_path.read_text(encoding="utf-8")
    memory = None
    if args.workers > 1 or args.scheduler:  # workers then read the meshes built here
        memory = _mesh_first(points, case, console)
    # finished points are reused only for the same case text: editing the case starts afresh
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    return execute(points, folder / f"points-{digest}", point_functions.evaluate,
                   (text, str(Path(case_path).resolve()), runs and str(Path(runs).resolve()),
                    str(cache_root().resolve())),
                   workers=args.workers, scheduler=args.scheduler, memory_bytes=memory, console=console)


def _mesh_first(points, case, console):
    """Build (or load) every point's mesh before solving, so memory is known from DOFs."""
    from femstudy.casefile import with_overrides
    from femstudy.meshing import build_femur_model
    from femstudy.sweep.points import estimated_dofs, estimated_memory_bytes

    need = {}
    for k, point in enumerate(points, 1):
        console.progress(f"mesh {k}/{len(points)}: {point.label}")
        c = with_overrides(case, point.overrides)
        model = build_femur_model(c)
        dofs = estimated_dofs(model.mesh.n_points, model.mesh.n_tets, c.mesh.order)
        need[point.id] = estimated_memory_bytes(dofs)
    return lambda point: need[point.id]


def _mesh_sweep(args) -> int:
    import json

    from femstudy import atomic
    from femstudy.casefile import load_case
    from femstudy.sweep import report
    from femstudy.sweep.spec import mesh_points

    case = load_case(args.file)
    orders = [1, 2] if args.order == "both" else [int(args.order)]
    refines = ["site", "uniform"] if args.refine == "both" else [args.refine]
    points = mesh_points(case, args.sizes, orders, refines)
    folder = args.out or Path("results") / f"sweep-{case.name}"
    records = _execute(args, points, case, args.file, folder)
    rows = [r["result"] for r in records]
    assessment = report.convergence(rows, args.target)
    atomic.write_text(folder / "sweep.csv", report.table_csv(rows, report.MESH_COLUMNS))
    atomic.write_text(folder / "convergence.json", json.dumps(assessment, indent=2, default=float))
    figures = report.plots(folder, rows, assessment)
    text = "\n".join([f"# Mesh convergence: {case.name}", "",
                      f"Static solve under the peak dynamic drilling load; site size scaled with the global size. "
                      f"Sizes {', '.join(f'{s:g}' for s in sorted(set(args.sizes), reverse=True))} mm.", "",
                      report.table_markdown(rows, report.MESH_COLUMNS), "", "## Convergence (three finest meshes)", "",
                      report.convergence_markdown(assessment, args.target), "",
                      " ".join(f"![{f}]({f})" for f in figures), ""])
    atomic.write_text(folder / "sweep.md", text)
    print(report.convergence_markdown(assessment, args.target))
    print(f"wrote {folder / 'sweep.md'}")
    return 0


def _parameter_sweep(args) -> int:
    from femstudy import atomic
    from femstudy.casefile import load_case
    from femstudy.sweep import report
    from femstudy.sweep.spec import read_parameter_sweep

    name, case_path, points = read_parameter_sweep(args.file)
    case = load_case(case_path)
    from femstudy.casefile import with_overrides

    for p in points:  # validate every point before any work
        with_overrides(case, p.overrides)
    folder = args.out or Path("results") / f"sweep-{name}"
    records = _execute(args, points, case, case_path, folder, runs=str(folder / "runs"))
    keys = list(dict.fromkeys(k for r in records for k in r["point"]["overrides"]))
    rows = [{**r["point"]["overrides"], **r["result"]} for r in records]
    columns = keys + ["mu_f", "mu_w", "peak_thrust_N", "peak_torque_Nmm", "max_deflection_mm_dynamic",
                      "max_deflection_mm_static", "max_deflection_mm_ratio", "max_von_mises_MPa_dynamic",
                      "max_von_mises_excl_MPa_dynamic", "max_von_mises_MPa_ratio", "dofs", "total_s"]
    atomic.write_text(folder / "sweep.csv", report.table_csv(rows, columns))
    table = report.table_markdown(rows, columns)
    atomic.write_text(folder / "sweep.md", f"# Parameter sweep: {name}\n\nCase {case_path}\n\n{table}\n")
    print(table)
    print(f"wrote {folder / 'sweep.md'}")
    return 0
