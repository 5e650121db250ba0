"""``femstudy uncertainty``: samples of one or more cases (a cohort of femurs or sites), on Dask.

The work is two kinds of independent points run by the sweeps' resumable executor
(:func:`femstudy.sweeps.execute.execute`: each finished point written at once, atomically, under
``<out>/points/``; a run started again skips the finished ones):

1. one point per case: the femur meshed (once; the mesh cache keeps it), assembled, its unit
   responses, the reduced basis trained on the design's stiffness points (stored beside the
   points) and the nominal sample;
2. chunks of samples per case (the first ``hole_samples`` in chunks of :data:`HOLE_CHUNK`, as
   each runs the hole models).

``workers`` > 1 runs them on a Dask ``LocalCluster`` of that many single-threaded worker
processes, each limited to ``memory_limit`` bytes (default: 80 % of the memory available at the
start, shared equally); ``scheduler`` sends them to a running Dask scheduler instead; one worker
runs them in this process. A worker keeps the femur it prepared last for the next chunks (one:
its memory is one femur's model, unit responses and reduced bases), and is not paused at Dask's
80 % mark (a worker holding its femur would never resume): it is restarted past 95 %.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import resource
import time
from os import PathLike
from pathlib import Path

import numpy as np

from femstudy.errors import UserError
from femstudy.meshing.cache import DEFAULT_CACHE_DIR
from femstudy.sweeps.execute import Point, execute
from femstudy.uncertainty import design
from femstudy.uncertainty.result import GLOBAL_OUTPUTS, OUTPUTS, FemurUncertainty, UncertaintyResult

log = logging.getLogger(__name__)

#: Samples per point: without and with the hole models.
CHUNK = 2048
STIFFNESS_CHUNK = 256
HOLE_CHUNK = 2
#: This process's last prepared femur (a Dask worker keeps it between chunks).
_BASES: dict = {}


def _key(*parts) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _job(case, names, method, samples, seed, hole_samples, folder: Path) -> dict:
    """What the points of one case need (picklable)."""
    from femstudy.meshing.surface import file_digest

    surface = case.surface_path()
    case_key = _key(case.model_dump(mode="json"), file_digest(surface) if surface else "builtin")
    design_key = _key(method, list(names), samples, seed)
    unit = design.unit_design(method, names, samples, seed)
    return {"case": case, "names": tuple(names), "unit": unit, "key": f"{case_key}-{design_key}", "samples": samples,
            "hole": min(hole_samples, len(unit)), "basis_file": folder / f"basis-{case_key}-{design_key}.npz"}


def _limit_threads(threads: int | None) -> None:
    if threads:
        from threadpoolctl import threadpool_limits

        from femstudy.fe.linsolve import load_runtimes

        load_runtimes()
        threadpool_limits(limits=threads)


def _base(job: dict, settings: dict):
    from femstudy.uncertainty.femur import femur_base

    if job["key"] not in _BASES:
        _limit_threads(settings["threads"])
        _BASES.clear()  # one femur per worker bounds its memory
        _BASES[job["key"]] = femur_base(job["case"], settings["cache_dir"], settings["solver"], settings["bones_dir"],
                                        settings["keep"], job["names"], job["unit"], job["basis_file"])
    return _BASES[job["key"]]


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _femur_point(point: Point, jobs: dict, settings: dict) -> dict:
    """Stage 1: the femur prepared, its basis trained and stored, the nominal sample (with the
    hole models when any sample runs them)."""
    from femstudy.uncertainty.femur import distribution_table, evaluate_samples
    from femstudy.uncertainty.inputs import nominal_values

    job = jobs[point.overrides["job"]]
    base = _base(job, settings)
    nominal = evaluate_samples(base, [nominal_values(base.case, base.loading.depth_mm)], [job["hole"] > 0])
    basis = base.basis
    reduced = None if basis is None else {
        "clamped_sets": len(basis.bases), "factorisations": basis.factorisations,
        "snapshots": sum(len(b.snapshots) for b in basis.bases.values()),
        "basis_vectors": sum(int(b.V.shape[1]) for b in basis.bases.values())}
    return {"nominal": {k: (v[0] if isinstance(v, list) else v) for k, v in nominal.items()},
            "inputs": distribution_table(base.distributions), "reduced": reduced, "prepare_s": base.seconds,
            "dofs": base.model.system.n_dofs, "peak_MB": _peak_mb()}


def _samples_point(point: Point, jobs: dict, settings: dict) -> dict:
    """Stage 2: one chunk of samples."""
    from femstudy.uncertainty.femur import evaluate_samples

    job = jobs[point.overrides["job"]]
    base = _base(job, settings)
    start, stop = point.overrides["start"], point.overrides["stop"]
    began = time.perf_counter()
    values = base.values(job["unit"][start:stop])
    out = evaluate_samples(base, values, [start + i < job["hole"] for i in range(stop - start)])
    out["inputs"] = {n: [v[n] for v in values] for n in base.names}
    out["seconds"] = time.perf_counter() - began
    out["peak_MB"] = _peak_mb()
    return out


def _stage(points, folder, evaluate, args, workers, scheduler):
    return execute(points, folder, evaluate, args, workers=1 if scheduler else workers, scheduler=scheduler,
                   label="uncertainty points")


def _chunks(n: int, hole: int, stiffness: bool) -> list[tuple[int, int]]:
    size = STIFFNESS_CHUNK if stiffness else CHUNK
    bounds = list(range(0, hole, HOLE_CHUNK)) + list(range(hole, n, size))
    return [(a, min(b, n)) for a, b in zip(bounds, bounds[1:] + [n]) if a < n]


def run_uncertainty(cases, out: str | PathLike | None = None, *, samples: int | None = None, method: str | None = None,
                inputs: tuple[str, ...] | None = None, hole_samples: int | None = None, seed: int | None = None,
                workers: int = 2, scheduler: str | None = None, memory_limit: float | None = None,
                cache_dir: str | PathLike = DEFAULT_CACHE_DIR, solver: str = "auto",
                bones_dir: str | PathLike | None = None, keep_solutions: bool = True) -> UncertaintyResult:
    """Sample the uncertain inputs of one or more cases and summarise their outputs.

    Parameters
    ----------
    cases : list of str, PathLike or Case
        Case files (or cases); several make a cohort (femurs, sites), summarised per case and pooled.
    out : str or PathLike, optional
        Results folder (default ``results/uncertainty-<first case>``); its ``points/`` make the
        run resumable.
    samples, method, inputs, hole_samples, seed : optional
        Override every case's ``[uncertainty]`` values (:class:`femstudy.casefile.UncertaintySpec`).
    workers : int
        Dask LocalCluster worker processes (1: in this process, no Dask).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``) instead of a LocalCluster.
    memory_limit : float, optional
        Bytes per LocalCluster worker (default 80 % of the available memory / workers).
    cache_dir, solver, bones_dir, keep_solutions
        As for :func:`femstudy.run_study`.

    Returns
    -------
    UncertaintyResult

    Examples
    --------
    >>> r = run_uncertainty(["cases/middiaphysis.toml"], samples=1000, inputs=("mu_f_factor",), workers=1)  # doctest: +SKIP
    >>> r.femurs[0].summary()["max_deflection_mm"]["p95"]                                                 # doctest: +SKIP
    """
    from femstudy.casefile import Case, load_case

    started = time.perf_counter()
    bones = None if bones_dir is None else Path(bones_dir)
    loaded = [c if isinstance(c, Case) else load_case(c, bones) for c in cases]
    if not loaded:
        raise UserError("give at least one case file")
    names_seen = [c.name for c in loaded]
    if len(set(names_seen)) != len(names_seen):
        raise UserError(f"the cases' names must differ (they name the results): {', '.join(names_seen)}")
    if workers < 1:
        raise UserError(f"--workers must be at least 1, got {workers}")
    folder = Path(out) if out is not None else Path("results") / f"uncertainty-{loaded[0].name}"
    points_dir = folder / "points"
    points_dir.mkdir(parents=True, exist_ok=True)
    jobs, methods = {}, set()
    for case in loaded:
        u = case.uncertainty
        m = method or u.method
        methods.add(m)
        n = samples or u.samples
        if m == "sobol" and n & (n - 1):
            raise UserError(f"a Sobol design needs a power of 2 base samples (its balance), got {n}")
        names = tuple(inputs) if inputs else tuple(u.inputs)
        job = _job(case, names, m, n, u.seed if seed is None else seed, u.hole_samples if hole_samples is None
                   else hole_samples, points_dir)
        jobs[job["key"]] = job
    if len(methods) > 1:
        raise UserError("the cases ask for different methods; give --method")
    the_method = methods.pop()

    cluster, address = None, scheduler
    limit = None
    if workers > 1 and scheduler is None:
        cluster, limit = _local_cluster(workers, memory_limit)
        address = cluster.scheduler_address
    threads = None if scheduler else max(1, (os.cpu_count() or 1) // workers)
    settings = {"cache_dir": Path(cache_dir), "solver": solver, "bones_dir": bones,
                "keep": Path(cache_dir) / "solutions" if keep_solutions else None, "threads": threads}
    try:
        femur_points = [Point("uncertainty-femur", {"job": k}, f"{j['case'].name}: femur, basis, nominal")
                        for k, j in jobs.items()]
        femur_records = _stage(femur_points, points_dir, _femur_point, (jobs, settings), workers, address)
        sample_points = [Point("uncertainty-samples", {"job": k, "start": a, "stop": b},
                               f"{j['case'].name}: samples {a}-{b - 1}")
                         for k, j in jobs.items()
                         for a, b in _chunks(len(j["unit"]), j["hole"], _varies_stiffness(j["names"]))]
        sample_records = _stage(sample_points, points_dir, _samples_point, (jobs, settings), workers, address)
    finally:
        if cluster is not None:
            cluster.close()
    femurs = []
    for job, record in zip(jobs.values(), femur_records):
        mine = [r["result"] for p, r in zip(sample_points, sample_records) if p.overrides["job"] == job["key"]]
        femurs.append(_femur_result(job, record["result"], mine, the_method))
    peak = max([r["result"]["peak_MB"] for r in femur_records + sample_records])
    execution = {"workers": workers, "scheduler": scheduler or ("LocalCluster" if cluster else "this process"),
                 "memory_limit_per_worker_bytes": limit, "threads_per_worker": threads,
                 "peak_worker_memory_MB": peak, "wall_s": time.perf_counter() - started}
    result = UncertaintyResult(the_method, int(next(iter(jobs.values()))["samples"]), tuple(femurs), execution,
                               folder)
    from femstudy.uncertainty.output import write_results

    files = write_results(result, folder)
    return UncertaintyResult(result.method, result.samples, result.femurs, result.execution, folder, files)


def _varies_stiffness(names) -> bool:
    from femstudy.distributions import STIFFNESS_INPUTS

    return any(n in STIFFNESS_INPUTS for n in names)


def _local_cluster(workers: int, memory_limit: float | None):
    try:
        from dask.distributed import LocalCluster
    except ImportError:
        raise UserError("more than one worker needs dask.distributed: pip install 'femstudy[cluster]' "
                        "(or --workers 1)") from None
    import psutil

    import dask

    limit = memory_limit or 0.8 * psutil.virtual_memory().available / workers
    dask.config.set({"distributed.worker.memory.pause": False})
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, memory_limit=int(limit),
                           dashboard_address=":0")  # any free port: none is published
    return cluster, int(limit)


def _femur_result(job: dict, femur: dict, chunks: list[dict], method: str) -> FemurUncertainty:
    names = job["names"]
    columns = {n: np.concatenate([c["inputs"][n] for c in chunks]) for n in names}
    skip = {"inputs", "seconds", "peak_MB", "margin_basis"}
    for col in chunks[0]:
        if col not in skip:
            columns[col] = np.concatenate([np.asarray(c[col], float) for c in chunks])
    margin_basis = next((c["margin_basis"] for c in chunks if c.get("margin_basis")), None)
    if method == "sobol":
        evaluated = [o for o in OUTPUTS if o in GLOBAL_OUTPUTS or np.all(np.isfinite(columns[o]))]
        sensitivity = {o: design.sobol_indices(names, columns[o], 0) for o in evaluated}
    else:
        sensitivity = {o: design.rank_correlations(names, job["unit"], columns[o]) for o in OUTPUTS}
    reduced = femur["reduced"]
    if reduced is not None:
        reduced = {**reduced, "largest_energy_error_bound": float(np.max(columns["energy_error_bound"])),
                   "largest_drill_point_bound_mm": float(np.max(columns["drill_point_bound_mm"])),
                   "solved_directly": int(np.sum(columns["solved_directly"]))}
    case = job["case"]
    return FemurUncertainty(case.name, case.geometry.surface, femur["inputs"], job["unit"], columns, femur["nominal"],
                            sensitivity, reduced, margin_basis,
                            {"prepare_s": femur["prepare_s"], "samples_s": float(sum(c["seconds"] for c in chunks))})
