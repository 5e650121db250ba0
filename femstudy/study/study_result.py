"""What one study produced, typed: :class:`StudyResult` and its parts.

Every field is a typed value; :meth:`StudyResult.to_json` is the one place the summary.json
document (a dict) is made, and report.md is rendered from that document
(:mod:`femstudy.study.report`), so a report can be rebuilt from a finished results folder.
Units: mm, N, N·mm, MPa, s.
"""

from __future__ import annotations

import platform
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

import numpy as np

from femstudy import __version__, fe
from femstudy.casefile import Case
from femstudy.hole.study import HoleResult
from femstudy.meshing import FemurModel
from femstudy.study import verdicts
from femstudy.study.loading import CaseLoading
from femstudy.study.results import LoadingResult, comparison
from femstudy.study.sensitivity import Sensitivity
from femstudy.study.verification import Verification

PACKAGES = ("numpy", "scipy", "scikit-fem", "pytetwild", "pyvista", "meshio", "mkl")


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

    scheme, vectors, indicator : the thesis-step march (femstudy.fe.transient); step_kept: the
                 march and its outputs were read from an earlier run of the same inputs
                 (femstudy.kept_answers)
    lowest_period_s, step_check : from the modal analysis; modes_kept: its modes were read back
                 from an earlier analysis of the same model (femstudy.fe.modal)
    resolved_* : the resolved run (step, steps, vectors, indicator, peak deflection and its
                 quasi-static counterpart [mm]); amplification = resolved / quasi-static peak;
                 resolved_kept: read from an earlier run of the same inputs (femstudy.kept_answers)
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
    resolved_kept: bool = False
    step_kept: bool = False

    @property
    def amplification(self) -> float | None:
        """Resolved / quasi-static peak of the maximum deflection."""
        if self.resolved_peak_mm is None or not self.quasi_static_peak_mm:
            return None
        return self.resolved_peak_mm / self.quasi_static_peak_mm

    @property
    def refactorisations(self) -> int:
        """Factorisations beyond the global one: a stepped thesis-step march, a failed resolved one."""
        failed = self.resolved_indicator is not None and bool(np.isnan(self.resolved_indicator))
        return int(self.scheme == "stepping") + int(failed)

    def as_dict(self) -> dict:
        out = {k: v for k, v in self.__dict__.items() if k != "step_check"}
        out["frequencies_Hz"] = [float(f) for f in self.frequencies_Hz]
        out["dynamic_amplification"] = self.amplification
        if self.step_check is not None:
            out["step_check"] = dict(self.step_check.__dict__)
        return out


@dataclass(frozen=True)
class SolverRecord:
    """How the global model was solved.

    element_order, dofs, linear_solver : the model and the solver of K_ff
    factorisations : of the global K_ff (0 when kept solutions served every solve) and of any
        stepped march; hole_factorisations those of the hole models (None without them)
    solves_from_kept_solutions : right-hand sides served by kept solutions (femstudy.fe.kept)
    assembly : wall times of the assembly phases [s]
    """

    element_order: int
    dofs: int
    linear_solver: str
    factorisations: int
    solves_from_kept_solutions: int
    assembly: dict[str, float]
    hole_factorisations: int | None = None

    def as_dict(self) -> dict:
        out = dict(self.__dict__)
        if self.hole_factorisations is None:
            del out["hole_factorisations"]
        return out


@dataclass(frozen=True)
class Timings:
    """Wall times of a study's stages [s]; ``hole_s`` and ``files_s`` are the parts an executor
    ran (None when there were none; ``files_s`` the figures' and the picture and fields', the
    longer of the two when they ran side by side in forked processes, else their sum),
    ``waited_for_parts_s`` the time the study waited for them,
    ``parallel`` whether they ran in other processes."""

    mesh_s: float
    assembly_s: float
    factor_s: float
    dynamic_s: float
    modal_s: float
    resolved_s: float
    hole_s: float | None
    files_s: float | None
    waited_for_parts_s: float
    parallel: bool
    total_s: float

    def as_dict(self) -> dict:
        return {("waited_for_lanes_s" if k == "waited_for_parts_s" else k): v for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class Figures:
    """The pictures of a results folder: the warp factor of the deformed femur and the files."""

    warp_factor: float
    files: tuple[str, ...]
    fields: tuple[str, ...]

    def as_dict(self) -> dict:
        return {"warp_factor": self.warp_factor, "files": list(self.files), "fields": list(self.fields)}


@dataclass(frozen=True, eq=False)
class StudyResult:
    """The outcome of :func:`femstudy.run_study`.

    Attributes
    ----------
    case : Case
    femur : FemurModel
        The meshed femur: frame (units, side, axes), drill site, mesh statistics and quality.
    loading : CaseLoading
        Both loadings and the conditions behind them (``loading.conditions.friction`` is
        (μ_f, μ_w)).
    solver : SolverRecord
    dynamic, static : LoadingResult
        Per-step series and exact peaks of each loading.
    dynamics : Dynamics
    hole : HoleResult or None
        Stresses near the drilled hole, when ``case.loads.application == "hole"``.
    verification : Verification or None
        The verdicts of the near-hole measures measured in the run
        (:mod:`femstudy.study.verification`), when the case asks for them.
    timings : Timings
    figures : Figures or None
        When a results folder was written with pictures.
    out_dir : Path or None
        The results folder, when one was written.
    mesh_convergence : dict or None
        What a recorded ``femstudy sweep`` of the case's settings says of its answers at this mesh
        size (:func:`femstudy.study.mesh_convergence.find`).
    sensitivity : Sensitivity or None
        How much each modelling choice moves the answers (:mod:`femstudy.study.sensitivity`).
    out_of_range : tuple of dict
        The plausibility gates the study failed and ran past with ``force``
        (:mod:`femstudy.study.plausibility`; empty for a study in range).
    created_utc : str
    """

    case: Case
    femur: FemurModel
    loading: CaseLoading
    solver: SolverRecord
    dynamic: LoadingResult
    static: LoadingResult
    dynamics: Dynamics
    hole: HoleResult | None
    verification: Verification | None
    timings: Timings
    created_utc: str
    figures: Figures | None = None
    out_dir: Path | None = None
    out_of_range: tuple = ()
    sensitivity: Sensitivity | None = None
    mesh_convergence: dict | None = None
    package_versions: dict[str, str | None] = field(default_factory=versions)

    def peak(self, quantity: str, loading: str = "dynamic"):
        """The :class:`~femstudy.study.results.Peak` of a quantity (e.g. "max_deflection_mm")."""
        return (self.dynamic if loading == "dynamic" else self.static).peak(quantity)

    def timeseries(self) -> list[dict]:
        """Both loadings' series, one dict per loading and step, keys with units."""
        from femstudy.study.results import timeseries_rows

        return timeseries_rows([self.dynamic, self.static])

    def margins(self) -> dict:
        """Margins to failure: the hole's, each row with its verdict and band and the governing
        ones (:func:`femstudy.study.verdicts.gate`), or per region from the patch's peaks."""
        if self.hole is not None:
            return verdicts.gate(self.hole.margins(), self.verification)
        return {"dynamic": self.dynamic.margins(), "static": self.static.margins()}

    def to_json(self) -> dict:
        """The summary.json document (inputs, versions, mesh, solver, peaks, ratios, margins, timings)."""
        from femstudy.jsonable import jsonable

        case, femur, loading = self.case, self.femur, self.loading
        cond, site = loading.conditions, femur.site
        mu_f, mu_w = cond.friction
        margins = self.margins()
        out = {
            "femstudy_version": __version__, "created_utc": self.created_utc, "versions": self.package_versions,
            "case_file": str(case.source) if case.source else None,
            "case": case.model_dump(mode="json"),
            "mesh": {**femur.stats, "quality": femur.quality, "surface": case.geometry.surface,
                     "length_mm": float(femur.frame.length_mm)},
            "frame": femur.frame.as_dict(),
            "site": {"name": case.site.name, "entry_point_mm": [float(x) for x in site.entry_point],
                     "direction": [float(x) for x in site.direction],
                     "outward_normal": [float(x) for x in site.outward_normal],
                     "cortical_thickness_mm": float(site.cortical_thickness_mm),
                     "beyond_cortex": site.beyond_cortex,
                     "load_patch_radius_mm": case.drill.diameter_mm / 2},
            "loading": {"feed_mm_s": cond.feed_mm_s, "spindle_rpm": cond.spindle_rpm,
                        "feed_per_rev_mm": cond.feed_per_rev_mm, "bone_set": cond.bone.name,
                        "mu_f": mu_f, "mu_w": mu_w, "growth_exponent": cond.growth_exponent,
                        "depth_mm": loading.depth_mm, "static_thrust_N": loading.static_thrust_N,
                        "static_torque_Nmm": loading.static_torque_Nmm,
                        "peak_thrust_N": float(loading.dynamic.thrust_N.max()),
                        "peak_torque_Nmm": float(loading.dynamic.torque_Nmm.max()),
                        "breakthrough_s": cond.phase_times()["breakthrough"]},
            "solver": self.solver.as_dict(),
            "dynamics": self.dynamics.as_dict(),
            "results": comparison(self.dynamic, self.static),
            "margins": margins,
            "timings": self.timings.as_dict(),
        }
        if self.hole is not None:
            out["hole"] = {**self.hole.to_json(), "margins": margins,
                           "verification": None if self.verification is None else self.verification.to_json()}
        if self.figures is not None:
            out["figures"] = self.figures.as_dict()
        if self.sensitivity is not None:
            out["sensitivity"] = self.sensitivity.to_json()
        if self.mesh_convergence is not None:
            out["mesh_convergence"] = self.mesh_convergence
        out["out_of_range"] = list(self.out_of_range)
        return jsonable(out)
