"""One study: case → :func:`~femstudy.study.global_model.prepare` (the femur meshed and
assembled) → load histories (:mod:`femstudy.study.loading`) → one factorisation → static,
transient, modal and resolved analyses → hole models → :class:`StudyResult` and its results
folder.

The clamped stiffness K_ff is factorised once. The static solve, the transient's reduced
basis (load-dependent Ritz vectors, femstudy.fe.transient), the modal analysis (shift-invert
about 0) and the resolved transient all use that factorisation; a second one (K̂) is made
only when a reduced march fails its check against the full equations. Every loading's
response is then read from one projection of the basis onto the output points
(femstudy.fe.outputs).

The hole models need only the static shapes K⁻¹P, and the results files only the thesis-step
march: each is handed to an executor (:mod:`femstudy.execution`) as soon as what it needs is
solved. By default it runs in this process when its result is needed; the command line's
:class:`femstudy.lanes.Lanes` runs them in forked processes beside the march and the modal and
resolved analyses, with the same numbers to round-off.

The results folder is built under a temporary name and renamed into place at the end
(:func:`femstudy.atomic.atomic_folder`), so an interrupted run never leaves a folder that
looks complete.
"""

from __future__ import annotations

import contextlib
import logging
import time
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from functools import partial
from os import PathLike
from pathlib import Path

import numpy as np

from femstudy import atomic, fe
from femstudy.casefile import Case, with_overrides
from femstudy.execution import Executor, InProcess
from femstudy.fe.linsolve import available_memory_bytes
from femstudy.kept_answers import kept_answer
from femstudy.meshing.cache import DEFAULT_CACHE_DIR
from femstudy.meshing.model import surface_file
from femstudy.study import feasibility, mesh_convergence, output, plausibility, sensitivity
from femstudy.study.femur import femur_spec
from femstudy.study.global_model import GlobalModel, prepare
from femstudy.study.loading import CaseLoading, case_loading, resolved_loading
from femstudy.study.results import LoadingResult
from femstudy.study.study_result import Dynamics, SolverRecord, StudyResult, Timings
from femstudy.study.verification import HoleAnalysis, analyse_hole

log = logging.getLogger(__name__)

#: The resolved run's basis is enriched to this error indicator (accepted below 1e-4; docs/solver.md).
RESOLVED_RTOL = 1e-5
#: Field frames a run writes at most (a frame is a full displacement field: 30,000 steps of
#: a resolved run would otherwise fill memory and disk).
MAX_FIELD_FRAMES = 100


def run_study(case: Case, out_dir: str | PathLike | None = None, *, mesh_size_mm: float | None = None,
              cache_dir: str | PathLike = DEFAULT_CACHE_DIR, solver: str = "auto",
              bones_dir: str | PathLike | None = None, force: bool = False, keep_solutions: bool = True,
              executor: Executor | None = None) -> StudyResult:
    """Run the drilling study of ``case``; write its results folder when ``out_dir`` is given.

    Parameters
    ----------
    case : Case
        From :func:`femstudy.casefile.load_case` or :func:`~femstudy.casefile.parse_case`.
    out_dir : str or PathLike, optional
        Results folder (replaced as a whole, atomically).
    mesh_size_mm : float, optional
        Overrides ``case.mesh.size_mm`` (validated like the case file's value).
    cache_dir : str or PathLike
        Mesh cache folder; also holds the kept solutions (``solutions/``).
    solver : str
        "auto" or a linear solver of :data:`femstudy.fe.linsolve.METHODS`.
    bones_dir : str or PathLike, optional
        Folder of calibrated bone sets named by ``case.drilling.bone``.
    force : bool
        Run even when the study is estimated to take very long (one that cannot fit in
        memory is refused regardless), or when an input or a result fails a plausibility gate
        (:mod:`femstudy.study.plausibility`): then it is marked out of range.
    keep_solutions : bool
        Serve the solves from the solutions an earlier run kept for the same stiffness matrices
        and keep this run's (:mod:`femstudy.fe.kept`): a repeated study, or one that changes only
        the load histories, then factorises nothing; the assembled model is kept and read back
        too. False assembles and factorises every time.
    executor : Executor, optional
        Runs the hole models and the writing of the figures and fields
        (:mod:`femstudy.execution`); by default they run in this process. The command line
        gives :class:`femstudy.lanes.Lanes`, which runs them in forked processes beside the
        global analyses, with the same numbers to round-off.

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
    start = time.perf_counter()
    cache_dir = Path(cache_dir)
    if mesh_size_mm is not None:  # so that summary.json echoes the size actually used
        case = with_overrides(case, {"mesh.size_mm": mesh_size_mm}, what="--mesh-size")
    surface = surface_file(femur_spec(case), cache_dir)
    feasibility.check(case, surface, available_memory_bytes(), force=force, cache_dir=cache_dir)
    out_of_range = plausibility.check_inputs(case, bones_dir, force)
    feasibility.keep_surface_size(surface, cache_dir)
    log.info("case '%s': building or loading the femur mesh", case.name)
    checked = time.perf_counter()
    model = prepare(case, cache_dir, keep_assembly=keep_solutions)
    out_of_range += plausibility.check_site(case, model.femur, force)
    site = model.femur.site
    loading = case_loading(case, site.cortical_thickness_mm, None if bones_dir is None else Path(bones_dir),
                           site.beyond_cortex)
    out_of_range += plausibility.check_loads(loading, force)
    dyn = loading.dynamic
    log.info("loads: dynamic peak %.1f N / %.1f N.mm, static %.1f N / %.1f N.mm, %d steps of %g s",
             dyn.thrust_N.max(), dyn.torque_Nmm.max(), loading.static_thrust_N, loading.static_torque_Nmm,
             len(loading.times_s) - 1, case.time.step_s)
    solutions = cache_dir / "solutions" if keep_solutions else None
    assembled = time.perf_counter()
    fs = model.factorize(solver, solutions)
    factorised = time.perf_counter()
    shapes = fs.factor.solve(model.patch.patterns[fs.bc.free])  # K⁻¹P: the static response to a unit thrust and torque
    executor = InProcess() if executor is None else executor

    with contextlib.ExitStack() as stack:
        folder = None if out_dir is None else stack.enter_context(atomic.atomic_folder(Path(out_dir)))
        stack.enter_context(executor)  # left first: no part outlives the folder it writes to
        hole_part = None
        unit_fields = fs.bc.expand(shapes)
        # what the hole models and the sensitivity's alternatives are computed from (femstudy.kept_answers):
        # the unit fields follow from the case and the femur (keyed by them: their round-off depends on
        # whether kept solutions served them)
        answers = cache_dir / "answers" if keep_solutions else None
        key = (case, loading, _femur_key(model.femur), solver)
        if case.loads.application == "hole":  # the global field per unit patch load drives the hole models
            inputs = loading.hole_inputs(case.materials.to_fe(), case.mesh.order, case.clamps.length_mm)
            hole_part = executor.start("hole models", partial(
                kept_answer, answers, "hole models", (*key, case.loads.verify), partial(
                    analyse_hole, inputs, model.femur, model.system, unit_fields, case.loads.hole_options(),
                    solver, solutions, case.loads.verify), HoleAnalysis.read_back))
        sensitivity_part = None
        if case.analysis.sensitivity:
            sensitivity_part = executor.start("sensitivity", partial(
                kept_answer, answers, "sensitivity", key, partial(
                    sensitivity.run_variants, case, model, loading, unit_fields, solver, solutions, cache_dir,
                    case.loads.application == "hole", bool(case.analysis.modes)), sensitivity.Variants.read_back))
        # the file parts start now, to import their plotting libraries while the step is computed
        # (on a core the march leaves idle when they fork), and are given the step when it is
        file_parts = () if folder is None else output.start_file_parts(executor, folder, model, loading.times_s)
        # the march and its outputs, a function of what key holds, read back when an earlier run kept them
        step = kept_answer(answers, "thesis step", key, partial(_thesis_step, case, fs, model, loading, shapes),
                           lambda kept: replace(kept, kept=True), _worth_keeping, newest=KEPT_STEPS)
        marched = time.perf_counter()
        if file_parts:
            log.info("writing results to %s", out_dir)
        for part in file_parts:
            part.give(step)
        dynamics, modal_done = _modes_and_resolved(case, loading, fs, model, shapes, step, answers, key)
        baseline = sensitivity.baseline_answers(fs, model, loading, dynamics.frequencies_Hz[0]
                                                if dynamics.frequencies_Hz else None) if sensitivity_part else None
        fs.factor.close()  # the global solves are done (parts forked with it hold its pages until they end)
        resolved = time.perf_counter()
        analysis = None if hole_part is None else hole_part.result()
        hole = None if analysis is None else analysis.result
        table = None
        if sensitivity_part is not None:
            runs = sensitivity_part.result()
            table = sensitivity.sensitivity_table(runs.variants, sensitivity.with_hole(baseline, runs.baseline_hole),
                                                  sensitivity.uncertainties(analysis),
                                                  -1 if hole is None else len(hole.stations) - 1, runs.shared_seconds,
                                                  runs.kept)
        figures = output.pictured(model, step, *(part.result() for part in file_parts)) if file_parts else None
        waited = time.perf_counter()
        solver_record = SolverRecord(model.system.order, model.system.n_dofs, fs.method,
                                     fs.factor.factorisations + dynamics.refactorisations, fs.factor.served,
                                     model.system.timings,
                                     None if analysis is None else analysis.factorisations)
        timings = Timings(mesh_s=checked - start + model.mesh_s,
                          assembly_s=assembled - checked - model.mesh_s,
                          factor_s=factorised - assembled, dynamic_s=marched - factorised,
                          modal_s=(modal_done or marched) - marched, resolved_s=resolved - (modal_done or marched),
                          hole_s=None if hole_part is None else hole_part.seconds,
                          files_s=((max if getattr(executor, "forking", False) else sum)(
                              part.seconds for part in file_parts) if file_parts else None),
                          waited_for_parts_s=waited - resolved, parallel=bool(getattr(executor, "forking", False)),
                          total_s=time.perf_counter() - start)
        result = StudyResult(case, model.femur, loading, solver_record, step.dynamic, step.static, dynamics, hole,
                             None if analysis is None else analysis.verification, timings,
                             datetime.now(timezone.utc).isoformat(timespec="seconds"), figures,
                             None if out_dir is None else Path(out_dir), sensitivity=table,
                             mesh_convergence=_mesh_convergence(case, model, cache_dir))
        out_of_range += plausibility.check_results(result.to_json(), model.femur.frame.length_mm, force)
        result = replace(result, out_of_range=tuple(out_of_range))
        if folder is not None:
            output.write_summary(folder, result)
    return result


def _femur_key(femur) -> tuple:
    """What of the femur its near-hole answers depend on: its mesh, clamps, site, frame, canal
    axis, surfaces and surface file's content (not its statistics' timings or file path)."""
    return (femur.mesh, femur.clamps, femur.site, femur.frame, femur.canal_axis, femur.surface,
            femur.stats.get("surface_sha256"))


def _mesh_convergence(case: Case, model: GlobalModel, cache_dir: Path) -> dict:
    """What a recorded sweep of this case's settings says about its answers at this mesh size
    (:mod:`femstudy.study.mesh_convergence`)."""
    stats = model.femur.stats
    h_rep = (float(stats["tet_volume_mm3"]) / model.system.n_tets) ** (1 / 3)
    site = case.mesh.site_size_mm if case.mesh.refine == "site" else h_rep
    measures = {"max_deflection_mm": h_rep, "drill_point_deflection_mm": h_rep,
                "max_von_mises_excl_MPa": h_rep, "hole_von_mises_excl_MPa": site,
                **{f"hole_von_mises_{d:g}mm_MPa": site for d in case.loads.distances_mm}}
    return mesh_convergence.find(case, stats["surface_sha256"], cache_dir, case.mesh.size_mm, measures)


@dataclass(frozen=True, eq=False)
class ThesisStep:
    """The dynamic and static loadings on the case's time grid, and what their files need.

    scheme, vectors, indicator : how the dynamic loading was marched (femstudy.fe.transient)
    basis : (n_dofs, m) spans every field written; von_mises_rows its von Mises projection
    fields : step index → displacement [mm] of the steps whose field is written or pictured
    static_u : the static loading's displacement [mm]
    kept : read from an earlier run of the same inputs (femstudy.kept_answers)
    """

    scheme: str
    vectors: int
    indicator: float
    dynamic: LoadingResult
    static: LoadingResult
    basis: np.ndarray
    von_mises_rows: np.ndarray
    fields: dict[int, np.ndarray]
    static_u: np.ndarray
    kept: bool = False

    @property
    def nbytes(self) -> int:
        """What its arrays hold [bytes]."""
        return (self.basis.nbytes + self.von_mises_rows.nbytes + self.static_u.nbytes
                + sum(u.nbytes for u in self.fields.values()))


#: Thesis steps kept in a cache at most (the newest: every code change keys a new one), and the
#: largest kept (the default study's is 55 MB: its von Mises rows are most of it).
KEPT_STEPS = 4
MAX_KEPT_STEP_BYTES = 2 ** 29


def _worth_keeping(step: ThesisStep) -> bool:
    return step.nbytes <= MAX_KEPT_STEP_BYTES


def _damping(case: Case) -> tuple[float, float]:
    """Rayleigh damping (α [1/s], β [s]) of the case."""
    return case.analysis.rayleigh_alpha_per_s, case.analysis.rayleigh_beta_s


def _thesis_step(case: Case, fs, model: GlobalModel, loading: CaseLoading, shapes: np.ndarray) -> ThesisStep:
    """March the dynamic loading (or take it quasi-static) and solve the static one, on the
    case's time grid; ``shapes`` = K⁻¹P of the patch (free DOFs)."""
    times, dyn = loading.times_s, loading.dynamic
    patch, channels = model.patch, model.channels
    amplitudes = np.column_stack([dyn.thrust_N, dyn.torque_Nmm])
    keep = _kept_steps(case, len(times), int(np.argmax(dyn.thrust_N)))
    recorder = fe.StepRecorder(channels, len(times), keep)
    if case.analysis.transient:
        log.info("dynamic loading: %s, Newmark average acceleration", loading.title)
        march = fe.solve_transient(fs, patch.patterns, amplitudes, times, damping=_damping(case), observer=recorder,
                                   static_shapes=shapes)
        scheme, vectors, indicator = march.scheme, march.n_vectors, march.indicator
    else:
        log.info("dynamic loading: %s, quasi-static (no inertia)", loading.title)
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


def _modes_and_resolved(case: Case, loading: CaseLoading, fs, model: GlobalModel, shapes: np.ndarray,
                        step: ThesisStep, answers: Path | None, key: tuple) -> tuple[Dynamics, float | None]:
    """The modal analysis and the resolved transient the case asks for, and the time the modal
    analysis ended (None without one). The resolved run, a function of what ``key`` holds, is
    read from ``answers`` when an earlier run kept it (femstudy.kept_answers)."""
    dynamics = Dynamics(step.scheme, step.vectors, step.indicator, step_kept=step.kept)
    if not case.analysis.modes:
        return dynamics, None
    log.info("modal analysis: lowest %d modes", case.analysis.modes)
    modes = fe.solve_modal(fs, k=case.analysis.modes)
    check = fe.step_check(float(modes.period_s[0]), case.time.step_s)
    dynamics = Dynamics(step.scheme, step.vectors, step.indicator, tuple(float(f) for f in modes.frequency_Hz),
                        check, modes_kept=modes.kept, step_kept=step.kept)
    modal_done = time.perf_counter()
    if case.analysis.resolved:
        found = kept_answer(answers, "resolved transient", key, partial(_resolved, case, loading, fs, model, shapes,
                                                                        dynamics),
                            lambda kept: {**kept, "resolved_kept": True})
        dynamics = replace(dynamics, **found)
    return dynamics, modal_done


def _resolved(case: Case, loading: CaseLoading, fs, model: GlobalModel, shapes: np.ndarray,
              dynamics: Dynamics) -> dict:
    """A transient whose step resolves the lowest mode, through breakthrough, with the loads'
    per-flute oscillation and release; its peak deflection against the quasi-static one (the
    fields of :class:`Dynamics` it sets).

    It starts at the window's first time from the quasi-static state, u0 = K⁻¹f(t0) and
    v0 = K⁻¹ḟ(t0): up to there the loads change over seconds, so the response is that state
    to within (f_load / f_1)² (~1 % for 50 Hz against a 560 Hz lowest mode)."""
    patch, channels, damping = model.patch, model.channels, _damping(case)
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
        stiffness = march.basis.T @ fs.stiffness_times(march.basis)
        resolved = fe.reduced_history(cheap, march.full_basis(), march.coordinates, metric=stiffness)
    else:  # stepped: nothing kept; measure the resolved run again through a recorder
        recorder = fe.StepRecorder(cheap, len(A))
        march = fe.solve_transient(fs, patch.patterns, A, history.time_s, damping=damping, u0=u0, v0=v0,
                                   observer=recorder, scheme="stepping", static_shapes=shapes)
        resolved = recorder.history()
    Q, R = np.linalg.qr(march.static_shapes)  # the quasi-static response K⁻¹P a(t) = Q (R a(t))
    quasi = fe.reduced_history(cheap, fs.bc.expand(Q), R @ A.T, metric=Q.T @ fs.stiffness_times(Q))
    return {"resolved_step_s": dt, "resolved_steps": len(A) - 1,
            "resolved_window_s": (float(history.time_s[0]), float(history.time_s[-1])),
            "resolved_vectors": march.n_vectors, "resolved_indicator": march.indicator,
            "resolved_peak_mm": resolved["deflection"].peak,
            "quasi_static_peak_mm": quasi["deflection"].peak,
            "resolved_drill_point_mm": resolved["drill_point"].peak,
            "quasi_static_drill_point_mm": quasi["drill_point"].peak,
            "flute_passing_Hz": loading.conditions.drill.flute_passing_hz(case.drilling.spindle_rpm)}
