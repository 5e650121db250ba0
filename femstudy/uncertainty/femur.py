"""One femur's uncertainty engine: the model solved once, then any number of samples.

:func:`femur_base` meshes (or reads the cache) and assembles the case's femur, serves its unit
thrust and torque responses K⁻¹P from the kept solutions of an earlier study (or factorises
once), and, when stiffness inputs vary, trains (or reads back) the reduced basis of
:mod:`.reduced`. :func:`evaluate_samples` then computes every sample's outputs:

* the load histories of the sample (:mod:`.loads`), and
* the global outputs from the unit responses (:mod:`.response`): the nominal ones for
  samples that change only loads, the reduced basis's (error-bounded) for the others;
* for the first ``hole_samples`` samples, the hole models (:func:`femstudy.hole.study.hole_stresses`
  driven by the sample's unit fields, materials, clamped length and station loads), read
  through :mod:`.hole_outputs`.

Units: mm, N, N·mm, MPa, s.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING
from pathlib import Path

import numpy as np

from femstudy.distributions import STIFFNESS_INPUTS, Distribution
from femstudy.uncertainty.inputs import distributions, nominal_values
from femstudy.uncertainty.loads import amplitudes, sample_conditions, sample_loading
from femstudy.uncertainty.reduced import RTOL, ReducedBases, StiffnessFamily, StiffnessPoint, train
from femstudy.uncertainty.response import Envelope, UnitResponses

if TYPE_CHECKING:
    from femstudy.casefile import Case
    from femstudy.study.global_model import GlobalModel
    from femstudy.study.loading import CaseLoading

log = logging.getLogger(__name__)

#: Output columns of every sample (units in the names); the hole's are NaN where not run.
GLOBAL_COLUMNS = ("max_deflection_mm", "drill_point_deflection_mm", "peak_thrust_N", "peak_torque_Nmm", "mu_f",
                  "mu_w", "growth_exponent", "energy_error_bound", "drill_point_bound_mm", "solved_directly")


@dataclass
class FemurBase:
    """A case's femur ready for samples.

    case, model, loading : the case, its :class:`femstudy.GlobalModel` and nominal :class:`femstudy.CaseLoading`
    units : nominal unit responses; distributions : input name → :class:`Distribution`
    basis : the reduced bases (None when no stiffness input varies)
    """

    case: Case
    model: GlobalModel
    loading: CaseLoading
    units: UnitResponses
    distributions: dict[str, Distribution]
    basis: ReducedBases | None
    solver: str
    keep: Path | None
    seconds: float

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.distributions)

    def values(self, unit: np.ndarray) -> list[dict]:
        """Input values of unit-cube samples (n, D), nominal for the inputs that do not vary."""
        nominal = nominal_values(self.case, self.loading.depth_mm)
        columns = {n: d.ppf(unit[:, k]) for k, (n, d) in enumerate(self.distributions.items())}
        return [{**nominal, **{n: float(c[i]) for n, c in columns.items()}} for i in range(len(unit))]


def femur_base(case, cache_dir: Path, solver: str = "auto", bones_dir: Path | None = None, keep: Path | None = None,
               names: tuple[str, ...] | None = None, design: np.ndarray | None = None,
               basis_file: Path | None = None) -> FemurBase:
    """Prepare ``case``'s femur for sampling; ``design`` (unit-cube samples) trains the reduced
    basis on its stiffness points, stored in (or read back from) ``basis_file``."""
    from femstudy.drilling import load_bone_set
    from femstudy.study.global_model import prepare
    from femstudy.study.loading import case_loading

    start = time.perf_counter()
    model = prepare(case, cache_dir)
    loading = case_loading(case, model.femur.site.cortical_thickness_mm, bones_dir)
    dists = distributions(case, load_bone_set(case.drilling.bone, bones_dir), loading.depth_mm, names)
    fs = model.factorize(solver, keep)
    try:
        shapes = fs.bc.expand(fs.factor.solve(model.patch.patterns[fs.bc.free]))
    finally:
        fs.factor.close()
    units = UnitResponses.of(shapes, model.patch)
    base = FemurBase(case, model, loading, units, dists, None, solver, keep, 0.0)
    if any(n in STIFFNESS_INPUTS for n in dists):
        base.basis = _basis(base, shapes, design, basis_file)
    base.seconds = time.perf_counter() - start
    return base


def _basis(base: FemurBase, shapes: np.ndarray, design: np.ndarray | None, basis_file: Path | None) -> ReducedBases:
    family = StiffnessFamily.of(base.model)
    nominal = StiffnessPoint(clamp_length_mm=base.case.clamps.length_mm)
    if basis_file is not None and Path(basis_file).is_file():
        with np.load(basis_file) as data:
            return ReducedBases.load(family, data)
    points = sorted({StiffnessPoint.of(v, nominal.clamp_length_mm) for v in base.values(design)},
                    key=lambda p: (p.clamp_length_mm, p.cortical, p.cancellous)) if design is not None else []
    bases = train(family, _training(points), nominal, shapes, base.solver)
    if basis_file is not None:
        from femstudy.atomic import atomic_path

        with atomic_path(basis_file) as tmp:
            with open(tmp, "wb") as handle:
                bases.save(handle)
    return bases


#: Most design points the greedy training visits (a deterministic, evenly spread subset); a
#: visit costs a small r × r solve, so a design's every point is visited up to this many.
TRAINING_POINTS = 100_000


def _training(points: list) -> list:
    if len(points) <= TRAINING_POINTS:
        return points
    return [points[i] for i in np.linspace(0, len(points) - 1, TRAINING_POINTS).round().astype(int)]


def evaluate_samples(base: FemurBase, values: list[dict], hole: list[bool]) -> dict:
    """Outputs of the samples ``values`` (:data:`GLOBAL_COLUMNS` and, where ``hole`` is True,
    :data:`femstudy.uncertainty.hole_outputs.COLUMNS`), as lists."""
    from femstudy.uncertainty.hole_outputs import COLUMNS as HOLE_COLUMNS

    loads = amplitudes(base.loading, values)
    n = len(values)
    out = {c: np.full(n, np.nan) for c in GLOBAL_COLUMNS + HOLE_COLUMNS}
    out["peak_thrust_N"], out["peak_torque_Nmm"] = loads[:, :, 0].max(axis=1), loads[:, :, 1].max(axis=1)
    for k, v in enumerate(values):
        cond = sample_conditions(base.loading, v)
        out["mu_f"][k], out["mu_w"][k] = cond.friction
        out["growth_exponent"][k] = cond.growth_exponent
    clamp = base.case.clamps.length_mm
    fields = {}
    if base.basis is None:
        envelope = Envelope.of(base.units, loads)
        out["max_deflection_mm"] = envelope.max_deflection_mm(loads).max(axis=1)
        out["drill_point_deflection_mm"] = base.units.drill_point_mm(loads).max(axis=1)
        out["energy_error_bound"][:] = 0.0
        out["drill_point_bound_mm"][:] = 0.0
        out["solved_directly"][:] = 0.0
    else:
        for k, v in enumerate(values):
            units, error, energy, point, direct = _stiffness_units(base, StiffnessPoint.of(v, clamp))
            out["max_deflection_mm"][k] = units.max_deflection_mm(loads[k]).max()
            out["drill_point_deflection_mm"][k] = units.drill_point_mm(loads[k]).max()
            out["energy_error_bound"][k] = float(np.max(error / np.maximum(energy, 1e-300)))
            out["drill_point_bound_mm"][k] = float(point * (np.abs(loads[k]) @ error).max())
            out["solved_directly"][k] = float(direct)
            if hole[k]:
                fields[k] = units.fields
    for k in np.flatnonzero(hole):
        unit_fields = fields.get(k, base.units.fields)
        row, basis = _hole(base, values[k], unit_fields)
        for c, x in row.items():
            out[c][k] = x
        out.setdefault("margin_basis", basis)
    basis = out.pop("margin_basis", None)
    result = {c: [float(x) for x in col] for c, col in out.items()}
    result["margin_basis"] = basis
    return result


def _stiffness_units(base: FemurBase, p: StiffnessPoint) -> tuple[UnitResponses, np.ndarray, np.ndarray, float, bool]:
    """Unit responses at ``p`` from the reduced basis of its clamped set with their energy-norm
    error bounds, energy norms and drill-point factor (:meth:`ReducedBases.evaluate`), or
    solved directly (zero error) when the bound fails or no basis covers the set."""
    try:
        fields, error, energy, point = base.basis.evaluate(p)
        if np.all(error <= RTOL * energy):
            return UnitResponses.of(fields, base.model.patch), error, energy, point, False
    except KeyError:
        pass
    log.info("stiffness point %s: no reduced basis meets %g here; solving directly", p, RTOL)
    return (UnitResponses.of(base.basis.family.solve(p, base.solver), base.model.patch), np.zeros(2), np.ones(2),
            0.0, True)


def _hole(base: FemurBase, values: dict, unit_fields: np.ndarray) -> tuple[dict, str]:
    """The hole models of one sample and its near-hole outputs."""
    from femstudy.hole.study import hole_stresses
    from femstudy.uncertainty.hole_outputs import hole_outputs

    case = base.case
    mats = case.materials.to_fe()
    stiff = StiffnessPoint.of(values, case.clamps.length_mm)
    materials = replace(mats, cortical=replace(mats.cortical, E_MPa=stiff.cortical * mats.cortical.E_MPa),
                        cancellous=replace(mats.cancellous, E_MPa=stiff.cancellous * mats.cancellous.E_MPa))
    nominal_stiffness = stiff == StiffnessPoint(clamp_length_mm=case.clamps.length_mm)
    inputs = sample_loading(base.loading, values).hole_inputs(materials, case.mesh.order, stiff.clamp_length_mm)
    result = hole_stresses(inputs, base.model.femur, base.model.system, unit_fields, case.loads.hole_options(),
                           base.solver, base.keep if nominal_stiffness else None)
    return hole_outputs(result)


def distribution_table(dists: dict[str, Distribution]) -> dict:
    """Input name → its distribution's description and source (for uncertainty.json)."""
    return {n: d.as_dict() for n, d in dists.items()}
