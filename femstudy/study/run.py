"""One study: case → femur model → load histories → one factorisation → static, transient,
modal and resolved analyses → hole models → :class:`StudyResult` and its results folder.

The clamped stiffness K_ff is factorised once. The static solve, the transient's reduced
basis (load-dependent Ritz vectors, femstudy.fe.transient), the modal analysis (shift-invert
about 0) and the resolved transient all use that factorisation; a second one (K̂) is made
only when a reduced march fails its check against the full equations. Every loading's
response is then read from one projection of the basis onto the output points
(femstudy.fe.outputs).

The hole models need only the static shapes K⁻¹P, and the results files only the thesis-step
march, so on a Linux machine with two or more cores each runs in a forked process as soon as
what it needs is solved, beside the march and the modal and resolved analyses
(:mod:`femstudy.lanes`); the numbers are those of a run in one process (``parallel=False``) to
round-off.

The results folder is built under a temporary name and renamed into place at the end
(:func:`femstudy.atomic.atomic_folder`), so an interrupted run never leaves a folder that
looks complete.
"""

from __future__ import annotations

import contextlib
import logging
import platform
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import partial
from importlib import metadata
from pathlib import Path

import numpy as np

from femstudy import __version__, atomic, fe
from femstudy.casefile import Case, with_overrides
from femstudy.femur_model import REGION_NAMES
from femstudy.hole import verdicts
from femstudy.hole.study import hole_stresses
from femstudy.lanes import Lanes
from femstudy.meshing.cache import DEFAULT_CACHE_DIR
from femstudy.fe.linsolve import available_memory_bytes
from femstudy.meshing.model import surface_file
from femstudy.study import feasibility, output, plausibility
from femstudy.study.femur import femur_model, femur_spec
from femstudy.study.loading import CaseLoading, case_loading, resolved_loading
from femstudy.study.results import LoadingResult, comparison

log = logging.getLogger(__name__)

#: The resolved run's basis is enriched to this error indicator (accepted below 1e-4; docs/solver.md).
RESOLVED_RTOL = 1e-5
#: Field frames a run writes at most (a frame is a full displacement field: 30,000 steps of
#: a resolved run would otherwise fill memory and disk).
MAX_FIELD_FRAMES = 100

PACKAGES = ("numpy", "scipy", "scikit-fem", "pytetwild", "pyvista", "meshio", "pypardiso")


def versions() -> dict:
    """Versions of Python, femstudy and the numerical packages used."""
    out = {"python": platform.python_version(), "femstudy": __version__}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


@dataclass(frozen=True)
class Dynamics:
    """How the transients ran and what inertia does.

    scheme, vectors, indicator : the thesis-step march (femstudy.fe.transient)
    lowest_period_s, step_check : from the modal analysis; modes_kept: its modes were read back
                 from an earlier analysis of the same model (femstudy.fe.modal)
    resolved_* : the resolved run (step, steps, vectors, indicator, peak deflection and its
                 quasi-static counterpart [mm]); amplification = resolved / quasi-static peak
    """

    scheme: str
    vectors: int
    indicator: float
    frequencies_Hz: tuple = ()
    step_check: fe.StepCheck | None = None
    resolved_step_s: float | None = None
    resolved_steps: int | None = None
    resolved_window_s: tuple | None = None
    resolved_vectors: int | None = None
    resolved_indicator: float | None = None
    resolved_peak_mm: float | None = None
    quasi_static_peak_mm: float | None = None
    resolved_drill_point_mm: float | None = None
    quasi_static_drill_point_mm: float | None = None
    flute_passing_Hz: float | None = None
    modes_kept: bool = False

    @property
    def amplification(self) -> float | None:
        """Resolved / quasi-static peak of the maximum deflection."""
        if self.resolved_peak_mm is None or not self.quasi_static_peak_mm:
            return None
        return self.resolved_peak_mm / self.quasi_static_peak_mm

    def as_dict(self) -> dict:
        out = {k: v for k, v in self.__dict__.items() if k != "step_check"}
        out["frequencies_Hz"] = [float(f) for f in self.frequencies_Hz]
        out["dynamic_amplification"] = self.amplification
        if self.step_check is not None:
            out["step_check"] = dict(self.step_check.__dict__)
        return out


@dataclass(frozen=True, eq=False)
class StudyResult:
    """The outcome of :func:`run_study`: the dynamic and static loadings' responses, the
    dynamics, and everything summary.json records (:meth:`to_json`).

    Attributes
    ----------
    case : Case
    dynamic, static : LoadingResult
        Per-step series and exact peaks of each loading.
    dynamics : Dynamics
    loading : CaseLoading
    out_dir : Path or None
        The results folder, when one was written.
    hole : HoleResult or None
        Stresses near the drilled hole (:func:`femstudy.hole.study.hole_stresses`), when
        ``case.loads.application == "hole"``.
    """

    case: Case
    dynamic: LoadingResult
    static: LoadingResult
    dynamics: Dynamics
    loading: CaseLoading
    summary: dict
    out_dir: Path | None = None
    hole: object = None  # femstudy.hole.study.HoleResult when loads.application = "hole"

    def to_json(self) -> dict:
        """The summary.json document (inputs, versions, mesh, solver, peaks, ratios, timings)."""
        from femstudy.jsonable import jsonable

        return jsonable(self.summary)

    def peak(self, quantity: str, loading: str = "dynamic"):
        """The :class:`~femstudy.study.results.Peak` of a quantity (e.g. "max_deflection_mm")."""
        return (self.dynamic if loading == "dynamic" else self.static).peak(quantity)

    def timeseries(self) -> list[dict]:
        """Both loadings' series, one dict per loading and step, keys with units."""
        from femstudy.study.results import timeseries_rows

        return timeseries_rows([self.dynamic, self.static])


def study_channels(system, patch, model, exclusion_radius_mm: float, clamp_length_mm: float) -> list:
    """The output points of a study: every node's |u|, the drill point's mean displacement,
    and every stress point's von Mises stress, with masks for the points more than the
    exclusion radius from the drill point and from the clamped ends, and per region."""
    from femstudy.fe.post import quadrature_points

    points = quadrature_points(system)
    nq = points.shape[1]
    points = points.reshape(-1, 3)
    heights = points @ model.frame.up
    nodes_up = system.nodes @ model.frame.up
    margin = clamp_length_mm + exclusion_radius_mm
    away = ((np.linalg.norm(points - patch.centre, axis=1) > exclusion_radius_mm)
            & (heights < nodes_up.max() - margin) & (heights > nodes_up.min() + margin))
    masks = {"outside": away}
    for code, name in REGION_NAMES.items():
        masks[name] = np.repeat(system.region == code, nq)
    return [fe.deflection_channel(system), fe.point_channel("drill_point", patch.mean, patch.centre),
            fe.von_mises_channel(system, masks)]


def run_study(case: Case, out_dir: Path | None = None, *, mesh_size_mm: float | None = None,
              cache_dir: Path = DEFAULT_CACHE_DIR, solver: str = "auto", bones_dir: Path | None = None,
              force: bool = False, keep_solutions: bool = True, parallel: bool = True) -> StudyResult:
    """Run the drilling study of ``case``; write its results folder when ``out_dir`` is given.

    Parameters
    ----------
    case : Case
        From :func:`femstudy.casefile.load_case` or :func:`~femstudy.casefile.parse_case`.
    out_dir : Path, optional
        Results folder (replaced as a whole, atomically).
    mesh_size_mm : float, optional
        Overrides ``case.mesh.size_mm``.
    cache_dir : Path
        Mesh cache folder; also holds the kept solutions (``solutions/``).
    solver : str
        "auto" or a linear solver of :data:`femstudy.fe.linsolve.METHODS`.
    bones_dir : Path, optional
        Folder of calibrated bone sets named by ``case.drilling.bone``.
    force : bool
        Run even when the study is estimated to take very long (one that cannot fit in
        memory is refused regardless), or when an input or a result fails a plausibility gate
        (:mod:`femstudy.study.plausibility`): then it is marked out of range.
    keep_solutions : bool
        Serve the solves from the solutions an earlier run kept for the same stiffness matrices
        and keep this run's (:mod:`femstudy.fe.kept`): a repeated study, or one that changes only
        the load histories, then factorises nothing. False factorises every time.
    parallel : bool
        Run the hole models, and the writing of the figures and fields, in forked processes
        beside the global analyses on a Linux machine with two or more cores
        (:mod:`femstudy.lanes`); False runs everything in this process, with the same numbers
        to round-off.

    Returns
    -------
    StudyResult

    Examples
    --------
    >>> import femstudy
    >>> case = femstudy.load_case("cases/middiaphysis.toml")                # doctest: +SKIP
    >>> result = femstudy.run_study(case, mesh_size_mm=16)                  # doctest: +SKIP
    >>> result.peak("max_deflection_mm").value                              # doctest: +SKIP
    0.0539
    """
    if mesh_size_mm is not None:  # validated, and so that summary.json echoes the size actually used
        case = with_overrides(case, {"mesh.size_mm": mesh_size_mm})
    clock = {"start": time.perf_counter()}
    feasibility.check(case, surface_file(femur_spec(case), cache_dir), available_memory_bytes(), force=force)
    out_of_range = plausibility.check_inputs(case, bones_dir, force)
    record_path = case.convergence_path()
    record = None if record_path is None else verdicts.read_record(record_path)  # a bad record fails now
    log.info("case '%s': building or loading the femur mesh", case.name)
    model = femur_model(case, cache_dir)
    out_of_range += plausibility.check_site(case, model, force)
    clock["mesh"] = time.perf_counter()

    loading = case_loading(case, model.site.cortical_thickness_mm, bones_dir)
    out_of_range += plausibility.check_loads(loading, force)
    times, dyn = loading.times_s, loading.dynamic
    log.info("loads: dynamic peak %.1f N / %.1f N.mm, static %.1f N / %.1f N.mm, %d steps of %g s",
             dyn.thrust_N.max(), dyn.torque_Nmm.max(), loading.static_thrust_N, loading.static_torque_Nmm,
             len(times) - 1, case.time.step_s)
    system = fe.assemble(model.mesh, case.materials.to_fe(), order=case.mesh.order, long_axis=model.frame.up)
    patch = fe.drill_patch(system, model.site, radius_mm=case.drill.diameter_mm / 2)
    channels = study_channels(system, patch, model, case.analysis.exclusion_radius_mm, case.clamps.length_mm)
    clock["assembly"] = time.perf_counter()
    solutions = cache_dir / "solutions" if keep_solutions else None
    fs = fe.factorize(system, fe.clamp(system, model.clamps), solver, keep=solutions)
    clock["factor"] = time.perf_counter()
    shapes = fs.factor.solve(patch.patterns[fs.bc.free])  # K⁻¹P: the static response to a unit thrust and torque
    damping = (case.analysis.rayleigh_alpha_per_s, case.analysis.rayleigh_beta_s)

    with contextlib.ExitStack() as stack:
        folder = None if out_dir is None else stack.enter_context(atomic.atomic_folder(Path(out_dir)))
        lanes = stack.enter_context(Lanes(parallel))  # left first: no child outlives the folder it writes to
        hole_lane = None
        if case.loads.application == "hole":  # the global field per unit patch load drives the hole models
            hole_lane = lanes.start("hole models", partial(
                hole_stresses, case, model, system, fs.bc.expand(shapes), loading, case.loads.hole_options(), solver,
                solutions))
        step = _thesis_step(case, fs, patch, channels, loading, shapes, damping)
        clock["dynamic"] = time.perf_counter()
        files_lane = None
        if folder is not None:
            log.info("writing results to %s", out_dir)
            files_lane = lanes.start("figures and fields", partial(
                output.write_files, folder, case, model, system, step.basis, step.von_mises_rows, step.fields,
                step.static_u, times, step.dynamic, step.static))
        dynamics = Dynamics(step.scheme, step.vectors, step.indicator)
        if case.analysis.modes:
            log.info("modal analysis: lowest %d modes", case.analysis.modes)
            modes = fe.solve_modal(fs, k=case.analysis.modes)
            check = fe.step_check(float(modes.period_s[0]), case.time.step_s)
            dynamics = Dynamics(step.scheme, step.vectors, step.indicator, tuple(float(f) for f in modes.frequency_Hz),
                                check, modes_kept=modes.kept)
            clock["modal"] = time.perf_counter()
            if case.analysis.resolved:
                dynamics = _resolved(case, loading, fs, patch, shapes, channels, damping, dynamics)
        fs.factor.close()  # the global solves are done (the lanes forked with it hold its pages until they end)
        clock["resolved"] = time.perf_counter()
        hole = None if hole_lane is None else hole_lane.result()
        figures = [] if files_lane is None else files_lane.result()
        clock["lanes"] = time.perf_counter()

        summary = _summary(case, model, loading, system, fs, step.dynamic, step.static, dynamics, clock)
        if hole is not None:  # the hole's measures replace the patch's mesh-dependent peak for margins
            summary["solver"]["hole_factorisations"] = sum(s.factorisations for s in hole.stations)
            summary["hole"] = hole.to_json()
            summary["hole"]["convergence"] = verdicts.applicable(record, verdicts.conditions(case))
            summary["margins"] = summary["hole"]["margins"] = verdicts.gate(hole.margins(),
                                                                            summary["hole"]["convergence"])
        summary["timings"].update(hole_s=hole_lane and hole_lane.seconds, files_s=files_lane and files_lane.seconds,
                                  waited_for_lanes_s=clock["lanes"] - clock["resolved"], parallel=lanes.forking)
        summary["out_of_range"] = out_of_range + plausibility.check_results(summary, model.frame.length_mm, force)
        summary["timings"]["total_s"] = time.perf_counter() - clock["start"]  # before writing the summary
        result = StudyResult(case, step.dynamic, step.static, dynamics, loading, summary, out_dir, hole)
        if folder is not None:
            output.write_summary(folder, result, model, figures)
    return result


@dataclass(frozen=True, eq=False)
class ThesisStep:
    """The dynamic and static loadings on the case's time grid, and what their files need.

    scheme, vectors, indicator : how the dynamic loading was marched (femstudy.fe.transient)
    basis : (n_dofs, m) spans every field written; von_mises_rows its von Mises projection
    fields : step index → displacement [mm] of the steps whose field is written or pictured
    static_u : the static loading's displacement [mm]
    """

    scheme: str
    vectors: int
    indicator: float
    dynamic: LoadingResult
    static: LoadingResult
    basis: np.ndarray
    von_mises_rows: np.ndarray
    fields: dict
    static_u: np.ndarray


def _thesis_step(case, fs, patch, channels, loading, shapes, damping) -> ThesisStep:
    """March the dynamic loading (or take it quasi-static) and solve the static one, on the
    case's time grid; ``shapes`` = K⁻¹P of the patch (free DOFs)."""
    times, dyn = loading.times_s, loading.dynamic
    amplitudes = np.column_stack([dyn.thrust_N, dyn.torque_Nmm])
    keep = _kept_steps(case, len(times), int(np.argmax(dyn.thrust_N)))
    recorder = fe.StepRecorder(channels, len(times), keep)
    if case.analysis.transient:
        log.info("dynamic loading: cutting + chip evacuation, Newmark average acceleration")
        march = fe.solve_transient(fs, patch.patterns, amplitudes, times, damping=damping, observer=recorder,
                                   static_shapes=shapes)
        scheme, vectors, indicator = march.scheme, march.n_vectors, march.indicator
    else:
        log.info("dynamic loading: cutting + chip evacuation, quasi-static (no inertia)")
        march = None
        scheme, vectors, indicator = "quasi-static", shapes.shape[1], 0.0
    basis = march.full_basis() if march is not None and march.scheme == "reduced" else \
        fs.bc.expand(np.linalg.qr(shapes)[0])
    projections = {ch.name: ch.project(basis) for ch in channels}
    static_u = fs.bc.expand(shapes @ [loading.static_thrust_N, loading.static_torque_Nmm])
    static_history = fe.reduced_history(channels, basis, (basis.T @ static_u)[:, None], projections)
    static = LoadingResult.from_history("static", times[:1], [loading.static_thrust_N], [loading.static_torque_Nmm],
                                        static_history)
    static = _constant(static, times, loading)
    if march is not None and march.scheme == "reduced":
        dynamic_history = fe.reduced_history(channels, basis, march.coordinates, projections)
        fields = {n: basis @ march.coordinates[:, n] for n in keep}
    elif march is not None:
        dynamic_history, fields = recorder.history(), recorder.fields
    else:
        coords = np.linalg.qr(shapes)[1] @ amplitudes.T  # basis = Q of shapes = Q R
        dynamic_history = fe.reduced_history(channels, basis, coords, projections)
        fields = {n: basis @ coords[:, n] for n in keep}
    dynamic = LoadingResult.from_history("dynamic", times, dyn.thrust_N, dyn.torque_Nmm, dynamic_history)
    return ThesisStep(scheme, vectors, indicator, dynamic, static, basis, projections["von_mises"], fields, static_u)


def _constant(static: LoadingResult, times, loading: CaseLoading) -> LoadingResult:
    """The static loading's single solution repeated on the time grid (its series are flat)."""
    n = len(times)
    return LoadingResult("static", np.asarray(times, float), np.full(n, loading.static_thrust_N),
                         np.full(n, loading.static_torque_Nmm), {q: np.full(n, v[0]) for q, v in static.series.items()},
                         static.peaks, static.region_peaks)


def _kept_steps(case: Case, n_steps: int, peak_step: int) -> set:
    """Steps whose full field is written (every fields_every-th and the last, at most about
    :data:`MAX_FIELD_FRAMES` of them) and pictured."""
    stride = max(case.output.fields_every, -(-n_steps // MAX_FIELD_FRAMES))
    if case.output.fields and stride > case.output.fields_every:
        log.info("writing the field every %d steps (not every %d): at most %d frames of %d steps",
                 stride, case.output.fields_every, MAX_FIELD_FRAMES, n_steps)
    keep = set(range(0, n_steps, stride)) | {n_steps - 1} if case.output.fields else set()
    if case.output.screenshot:
        keep.add(peak_step)
    return keep


def _resolved(case, loading, fs, patch, shapes, channels, damping, dynamics: Dynamics) -> Dynamics:
    """A transient whose step resolves the lowest mode, through breakthrough, with the loads'
    per-flute oscillation and release; its peak deflection against the quasi-static one.

    It starts at the window's first time from the quasi-static state, u0 = K⁻¹f(t0) and
    v0 = K⁻¹ḟ(t0): up to there the loads change over seconds, so the response is that state
    to within (f_load / f_1)² (~1 % for 50 Hz against a 560 Hz lowest mode)."""
    period = dynamics.step_check.lowest_period_s
    dt = period / case.analysis.steps_per_period
    history = resolved_loading(case, loading, dt)
    A = np.column_stack([history.thrust_N, history.torque_Nmm])
    log.info("resolved transient: %d steps of %.3g ms (%d per lowest period) from %.2f to %.2f s, per-flute "
             "oscillation and breakthrough release included", len(A) - 1, 1e3 * dt, case.analysis.steps_per_period,
             history.time_s[0], history.time_s[-1])
    u0, v0 = fs.bc.expand(shapes @ np.column_stack([A[0], (A[1] - A[0]) / dt])).T  # shapes = K⁻¹P (free DOFs)
    march = fe.solve_transient(fs, patch.patterns, A, history.time_s, damping=damping, u0=u0, v0=v0,
                               rtol=RESOLVED_RTOL, static_shapes=shapes)
    cheap = [ch for ch in channels if ch.name in ("deflection", "drill_point")]
    if march.scheme == "reduced":
        stiffness = march.basis.T @ (fs.K @ march.basis)
        resolved = fe.reduced_history(cheap, march.full_basis(), march.coordinates, metric=stiffness)
    else:  # stepped: nothing kept; measure the resolved run again through a recorder
        recorder = fe.StepRecorder(cheap, len(A))
        march = fe.solve_transient(fs, patch.patterns, A, history.time_s, damping=damping, u0=u0, v0=v0,
                                   observer=recorder, scheme="stepping", static_shapes=shapes)
        resolved = recorder.history()
    Q, R = np.linalg.qr(march.static_shapes)  # the quasi-static response K⁻¹P a(t) = Q (R a(t))
    quasi = fe.reduced_history(cheap, fs.bc.expand(Q), R @ A.T, metric=Q.T @ (fs.K @ Q))
    return Dynamics(**{**dynamics.__dict__, "resolved_step_s": dt, "resolved_steps": len(A) - 1,
                       "resolved_window_s": (float(history.time_s[0]), float(history.time_s[-1])),
                       "resolved_vectors": march.n_vectors, "resolved_indicator": march.indicator,
                       "resolved_peak_mm": resolved["deflection"].peak,
                       "quasi_static_peak_mm": quasi["deflection"].peak,
                       "resolved_drill_point_mm": resolved["drill_point"].peak,
                       "quasi_static_drill_point_mm": quasi["drill_point"].peak,
                       "flute_passing_Hz": loading.conditions.drill.flute_passing_hz(case.drilling.spindle_rpm)})


def _summary(case, model, loading, system, fs, dynamic, static, dynamics, clock) -> dict:
    cond = loading.conditions
    mu_f, mu_w = cond.friction
    site = model.site
    timing = {"mesh_s": clock["mesh"] - clock["start"], "assembly_s": clock["assembly"] - clock["mesh"],
              "factor_s": clock["factor"] - clock["assembly"], "dynamic_s": clock["dynamic"] - clock["factor"],
              "modal_s": clock.get("modal", clock["dynamic"]) - clock["dynamic"],
              "resolved_s": clock["resolved"] - clock.get("modal", clock["dynamic"])}
    return {
        "femstudy_version": __version__, "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "versions": versions(),
        "case_file": str(case.source) if case.source else None,
        "case": case.model_dump(mode="json"),
        "mesh": {**model.stats, "quality": model.quality, "surface": case.geometry.surface,
                 "length_mm": float(model.frame.length_mm)},
        "site": {"name": case.site.name, "entry_point_mm": [float(x) for x in site.entry_point],
                 "direction": [float(x) for x in site.direction],
                 "outward_normal": [float(x) for x in site.outward_normal],
                 "cortical_thickness_mm": float(site.cortical_thickness_mm),
                 "load_patch_radius_mm": case.drill.diameter_mm / 2},
        "loading": {"feed_mm_s": cond.feed_mm_s, "spindle_rpm": cond.spindle_rpm,
                    "feed_per_rev_mm": cond.feed_per_rev_mm, "bone_set": cond.bone.name,
                    "mu_f": mu_f, "mu_w": mu_w, "growth_exponent": cond.growth_exponent,
                    "depth_mm": loading.depth_mm, "static_thrust_N": loading.static_thrust_N,
                    "static_torque_Nmm": loading.static_torque_Nmm,
                    "peak_thrust_N": float(loading.dynamic.thrust_N.max()),
                    "peak_torque_Nmm": float(loading.dynamic.torque_Nmm.max()),
                    "breakthrough_s": cond.phase_times()["breakthrough"]},
        "solver": {"element_order": system.order, "dofs": system.n_dofs, "linear_solver": fs.method,
                   "factorisations": fs.factor.factorisations + (dynamics.scheme == "stepping") + (
                       dynamics.resolved_indicator is not None and np.isnan(dynamics.resolved_indicator)),
                   "solves_from_kept_solutions": fs.factor.served,
                   "assembly": system.timings},
        "dynamics": dynamics.as_dict(),
        "results": comparison(dynamic, static),
        "margins": {"dynamic": dynamic.margins(), "static": static.margins()},
        "timings": timing,
    }
