"""``sweep``: a mesh-convergence ladder of a case, or a parameter sweep file, run to a folder.

Points run locally one after another, in a process pool (``workers``) or on a Dask cluster
(``scheduler``), resumably (femstudy.sweeps.execute). With several workers the femur meshes
are built here first, so that workers read them from ``cache_dir`` (TetWild is not
deterministic) and so that each point's memory is known from its DOFs.
"""

from __future__ import annotations

import hashlib
import json
import logging
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from femstudy import atomic
from femstudy.errors import UserError, require
from femstudy.meshing.cache import DEFAULT_CACHE_DIR
from femstudy.sweeps import report

log = logging.getLogger(__name__)

#: A Dask scheduler address: protocol://host:port (tcp, tls, ucx, ws, wss, inproc) or host:port.
SCHEDULER_ADDRESS = re.compile(r"^(?:(?:tcp|tls|ucx|ws|wss)://)?\[?[A-Za-z0-9_.:-]+\]?:\d{1,5}/?$|^inproc://\S+$")

#: Columns of a parameter sweep's table after the swept keys.
STUDY_COLUMNS = ["mu_f", "mu_w", "peak_thrust_N", "peak_torque_Nmm", "max_deflection_mm_dynamic",
                 "max_deflection_mm_static", "max_deflection_mm_ratio", "max_von_mises_MPa_dynamic",
                 "max_von_mises_excl_MPa_dynamic", "max_von_mises_MPa_ratio", "dofs", "total_s"]


@dataclass(frozen=True)
class SweepResult:
    """A finished sweep.

    kind        : "mesh" (convergence ladder) or "parameter"
    rows        : one dict per point, units in the keys (the table's rows)
    columns     : the table's columns
    convergence : per (order, refinement) group, per quantity, the assessment (mesh sweeps)
    folder      : where sweep.csv, sweep.md (and convergence.json, figures) were written
    text        : sweep.md's content
    """

    kind: str
    rows: list[dict[str, Any]]
    columns: list[str]
    convergence: dict[str, dict[str, Any]]
    folder: Path
    text: str

    def to_json(self) -> dict:
        return {"kind": self.kind, "rows": self.rows, "convergence": self.convergence, "folder": str(self.folder)}


def sweep(file: Path, sizes: list[float] | None = None, *, order: str = "2", refine: str = "site",
          target: float = 0.02, workers: int = 1, scheduler: str | None = None, out: Path | None = None,
          cache_dir: Path = DEFAULT_CACHE_DIR, solver: str = "auto", bones_dir: Path | None = None) -> SweepResult:
    """Run a mesh-convergence sweep of a case file (``sizes`` given) or a parameter sweep file.

    Parameters
    ----------
    file : Path
        A case file (with ``sizes``) or a sweep file (``case = ...``, ``[grid]``/``[[point]]``).
    sizes : list of float, optional
        Global element sizes [mm] of a mesh sweep.
    order : {"1", "2", "both"}
    refine : {"site", "uniform", "both"}
    target : float
        Relative error on max deflection for the recommended size.
    workers, scheduler
        Local worker processes, or a Dask scheduler address.
    out : Path, optional
        Sweep folder (default results/sweep-<name>).
    cache_dir, solver, bones_dir
        As for :func:`femstudy.run_study`.

    Returns
    -------
    SweepResult

    Examples
    --------
    >>> result = sweep(Path("cases/middiaphysis.toml"), [16, 12, 8])   # doctest: +SKIP
    >>> result.convergence["P2-site"]["quantities"]["max_deflection_mm"]["verdict"]   # doctest: +SKIP
    'converged'
    """
    require(Path(file).is_file(), f"{file} does not exist" if not Path(file).is_dir() else
            f"{file} is a folder; give a case file or a sweep file")
    require(workers >= 1, f"--workers must be at least 1, got {workers}")
    require(0 < target < 1, f"--target is a relative error in (0, 1), got {target}")
    require(scheduler is None or SCHEDULER_ADDRESS.match(scheduler) is not None,
            f"--scheduler '{scheduler}' is not a Dask scheduler address; give one like tcp://host:8786")
    try:
        is_sweep_file = "case" in tomllib.loads(Path(file).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read {file}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{file}: TOML syntax error: {exc}") from None
    options = dict(workers=workers, scheduler=scheduler, cache_dir=Path(cache_dir), solver=solver, bones_dir=bones_dir)
    if is_sweep_file:
        require(sizes is None, "--sizes belongs to a mesh sweep of a case file, not to a sweep file")
        return _parameter_sweep(Path(file), out, options)
    require(sizes is not None, "a mesh-convergence sweep needs --sizes, e.g. --sizes 32,16,8,6,4")
    return _mesh_sweep(Path(file), sizes, order, refine, target, out, options)


def _execute(points, case, case_path: Path, folder: Path, options: dict, runs=None):
    from femstudy.sweeps import points as point_functions
    from femstudy.sweeps.execute import execute

    memory = None
    if options["workers"] > 1 or options["scheduler"]:  # workers then read the meshes built here
        memory = _mesh_first(points, case, options["cache_dir"])
    text = case_path.read_text(encoding="utf-8")
    # finished points are reused only for the same case text: editing the case starts afresh
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    context = point_functions.Context(text, str(case_path.resolve()), runs and str(Path(runs).resolve()),
                                      str(Path(options["cache_dir"]).resolve()), options["solver"],
                                      options["bones_dir"] and str(Path(options["bones_dir"]).resolve()))
    return execute(points, folder / f"points-{digest}", point_functions.evaluate, (context,),
                   workers=options["workers"], scheduler=options["scheduler"], memory_bytes=memory)


def _preflight(points, case, options: dict) -> None:
    """Judge every point before the first one runs (femstudy.study.feasibility.preflight):
    one impossible point refuses the sweep, naming it."""
    from femstudy.casefile import with_overrides
    from femstudy.study.feasibility import preflight

    for point in points:
        try:
            preflight(with_overrides(case, point.overrides), options["cache_dir"], options["bones_dir"],
                      forceable=False)
        except UserError as exc:
            raise UserError(f"sweep point {point.label}: {exc}") from None


def _mesh_first(points, case, cache_dir: Path):
    """Build (or load) every point's mesh before solving, so memory is known from DOFs."""
    from femstudy.casefile import with_overrides
    from femstudy.study.femur import femur_model
    from femstudy.study.feasibility import factorisation_bytes
    from femstudy.sweeps.points import estimated_dofs

    need = {}
    for k, point in enumerate(points, 1):
        log.info("mesh %d/%d: %s", k, len(points), point.label, extra={"progress": ("meshes", k, len(points))})
        c = with_overrides(case, point.overrides)
        model = femur_model(c, cache_dir)
        need[point.id] = factorisation_bytes(estimated_dofs(model.mesh.n_points, model.mesh.n_tets, c.mesh.order))
    return lambda point: need[point.id]


def _mesh_sweep(case_path: Path, sizes, order, refine, target, out, options) -> SweepResult:
    from femstudy.casefile import load_case
    from femstudy.sweeps.spec import mesh_points

    case = load_case(case_path, options["bones_dir"])
    orders = [1, 2] if order == "both" else [int(order)]
    refines = ["site", "uniform"] if refine == "both" else [refine]
    points = mesh_points(case, sizes, orders, refines)
    _preflight(points, case, options)
    folder = _claim(out or Path("results") / f"sweep-{case.name}", case_path, options)
    rows = [{"point": r["point"]["label"], **r["result"]} for r in _execute(points, case, case_path, folder, options)]
    assessment = report.convergence(rows, target)
    _record(case, sizes, assessment, options["cache_dir"], case_path)
    atomic.write_text(folder / "sweep.csv", report.table_csv(rows, report.MESH_COLUMNS))
    atomic.write_text(folder / "convergence.json", json.dumps(assessment, indent=2, default=float))
    figures = report.plots(folder, rows, assessment)
    text = "\n".join([f"# Mesh convergence: {case.name}", "",
                      f"Static solve under the peak dynamic drilling load; site size scaled with the global size. "
                      f"Sizes {', '.join(f'{s:g}' for s in sorted(set(sizes), reverse=True))} mm; the middle size "
                      "meshed three times (\"remeshed\") to measure TetWild's remeshing noise; the hole models keep "
                      "the case's refinement at every size (each run verifies them itself).", "",
                      report.table_markdown(rows, report.MESH_COLUMNS), "", "## Convergence (three finest meshes)", "",
                      report.convergence_markdown(assessment, target), "",
                      " ".join(f"![{f}]({f})" for f in figures), ""])
    atomic.write_text(folder / "sweep.md", text)
    return SweepResult("mesh", rows, report.MESH_COLUMNS, assessment, folder, text)


def _record(case, sizes, assessment: dict, cache_dir: Path, case_path: Path) -> None:
    """Store each group's verdicts in the cache, for the runs of this case's settings to pick up
    (:mod:`femstudy.study.mesh_convergence`)."""
    from femstudy.casefile import with_overrides
    from femstudy.meshing.model import surface_file
    from femstudy.meshing.surface import file_digest
    from femstudy.study.femur import femur_spec
    from femstudy.study.mesh_convergence import write_record

    digest = file_digest(surface_file(femur_spec(case), cache_dir))
    command = f"femstudy sweep {case_path} --sizes {','.join(f'{s:g}' for s in sorted(set(sizes), reverse=True))}"
    for group, entry in assessment.items():
        order, refine = group[1:].split("-")
        variant = with_overrides(case, {"mesh.order": int(order), "mesh.refine": refine})
        write_record(variant, digest, cache_dir, group, entry, [float(s) for s in sizes], f"{command} ({group})")


def _claim(folder: Path, case_path: Path, options: dict, *inputs) -> Path:
    """The sweep's folder, checked and marked as femstudy's (it resumes: femstudy.writable.claim_folder)."""
    from femstudy.writable import claim_folder

    return claim_folder(folder, "the sweep", inputs=[case_path, *inputs], cache_dir=options["cache_dir"])


def _parameter_sweep(path: Path, out, options) -> SweepResult:
    from femstudy.casefile import load_case, with_overrides
    from femstudy.sweeps.spec import read_parameter_sweep

    name, case_path, points = read_parameter_sweep(path)
    case = load_case(case_path, options["bones_dir"])
    for p in points:  # validate every point before any work
        with_overrides(case, p.overrides)
    _preflight(points, case, options)
    folder = _claim(out or Path("results") / f"sweep-{name}", case_path, options, path)
    records = _execute(points, case, case_path, folder, options, runs=str(folder / "runs"))
    keys = list(dict.fromkeys(k for r in records for k in r["point"]["overrides"]))
    rows = [{**r["point"]["overrides"], **r["result"]} for r in records]
    columns = keys + STUDY_COLUMNS
    atomic.write_text(folder / "sweep.csv", report.table_csv(rows, columns))
    table = report.table_markdown(rows, columns)
    text = f"# Parameter sweep: {name}\n\nCase {case_path}\n\n{table}\n"
    atomic.write_text(folder / "sweep.md", text)
    return SweepResult("parameter", rows, columns, {}, folder, text)
