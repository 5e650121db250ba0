"""femstudy uncertainty: the Sobol analysis against an analytic function, the linear-load shortcut
and the reduced basis against direct solves, the distributions' sources, and a resumable run."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from femstudy.casefile import parse_case
from femstudy.errors import UserError
from femstudy.uncertainty import design
from femstudy.distributions import INPUTS
from femstudy.uncertainty.inputs import default_distributions

CASE = """
name = "unc"
[mesh]
size_mm = 16.0
order = 1
[loads]
application = "{application}"
stations = 1
refinement = 0.5
distances_mm = [1.0, 2.0]
exclusion_radii_mm = [1.0, 2.0]
[time]
end_s = 3.0
step_s = 0.25
[analysis]
modes = 0
resolved = false
[uncertainty]
samples = {samples}
"""


def coarse_case(application="surface_patch", samples=64):
    return parse_case(CASE.format(application=application, samples=samples))


@pytest.fixture(scope="module")
def base(mesh_cache):
    """A coarse femur ready for samples, with every stiffness input varying (a small design)."""
    from femstudy.uncertainty.femur import femur_base

    case = coarse_case()
    names = tuple(INPUTS)
    unit = design.unit_design("montecarlo", names, 24, 3)
    return femur_base(case, mesh_cache, names=names, design=unit), unit


def ishigami(x, a=7.0, b=0.1):
    return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])


def test_sobol_indices_of_the_ishigami_function_match_the_analytic_values():
    # Ishigami & Homma (1990), a = 7, b = 0.1: V = a²/8 + bπ⁴/5 + b²π⁸/18 + 1/2,
    # V1 = (1 + bπ⁴/5)²/2, V2 = a²/8, V13 = b²π⁸(1/18 − 1/50)
    a, b = 7.0, 0.1
    V = a * a / 8 + b * math.pi ** 4 / 5 + b * b * math.pi ** 8 / 18 + 0.5
    V1, V2, V13 = (1 + b * math.pi ** 4 / 5) ** 2 / 2, a * a / 8, b * b * math.pi ** 8 * (1 / 18 - 1 / 50)
    exact = {"x1": (V1 / V, (V1 + V13) / V), "x2": (V2 / V, V2 / V), "x3": (0.0, V13 / V)}
    names = ("x1", "x2", "x3")
    unit = design.unit_design("sobol", names, 4096, seed=1)
    indices = design.sobol_indices(names, ishigami(-math.pi + 2 * math.pi * unit), seed=1)
    for n, (s1, st) in exact.items():
        got = indices[n]
        assert abs(got["S1"] - s1) < max(2 * got["S1_conf"], 0.02), (n, got, s1)
        assert abs(got["ST"] - st) < max(2 * got["ST_conf"], 0.02), (n, got, st)
        assert 0 < got["S1_conf"] < 0.1 and 0 < got["ST_conf"] < 0.1


def test_every_default_distribution_cites_its_source_and_a_case_may_replace_it():
    from femstudy.drilling import load_bone_set

    case = parse_case('name = "x"\n[uncertainty.distributions.clamp_length_mm]\ndistribution = "uniform"\n'
                      'low = 10\nhigh = 14\nsource = "our fixture"\n')
    defaults = default_distributions(case, load_bone_set("human"), 6.0)
    assert set(defaults) == set(INPUTS)
    for name, d in defaults.items():
        assert len(d.source) > 20, name
        assert np.all(np.isfinite(d.ppf(np.array([0.01, 0.5, 0.99]))))
    assert "Table B-1" in defaults["mu_f_factor"].source and "Table 2-5" in defaults["cancellous_modulus_factor"].source
    # the median of a factor is 1: the nominal case is the centre of its distribution
    assert defaults["mu_w_factor"].ppf(np.array([0.5]))[0] == pytest.approx(1.0)
    from femstudy.uncertainty.inputs import distributions

    chosen = distributions(case, load_bone_set("human"), 6.0, ("clamp_length_mm",))
    assert chosen["clamp_length_mm"].params == (10.0, 14.0) and chosen["clamp_length_mm"].source == "our fixture"


@pytest.mark.parametrize("text, message", [
    ('[uncertainty]\ninputs = ["mu_q"]', "unknown uncertain input"),
    ('[uncertainty.distributions.mu_f_factor]\ndistribution = "normal"\nmean = 1', "needs mean and sd"),
    ('[uncertainty]\nmethod = "latin"', "uncertainty.method"),
])
def test_a_bad_uncertainty_table_is_one_clear_error(text, message):
    with pytest.raises(UserError, match=message):
        parse_case('name = "x"\n' + text)


def test_the_linear_load_shortcut_equals_direct_solves(base):
    from femstudy.uncertainty.loads import sample_loading
    from femstudy.uncertainty.response import Envelope

    femur, unit = base
    model = femur.model
    fs = model.factorize()
    values = femur.values(unit[:4])
    for v in values:
        v.update(cortical_modulus_factor=1.0, cancellous_modulus_factor=1.0, clamp_length_mm=20.0)
    loads = np.stack([np.column_stack([sample_loading(femur.loading, v).dynamic.thrust_N,
                                       sample_loading(femur.loading, v).dynamic.torque_Nmm]) for v in values])
    envelope = Envelope.of(femur.units, loads)
    assert 0 < len(envelope.nodes) < len(model.system.nodes) / 20
    fast = envelope.max_deflection_mm(loads)
    fast_point = femur.units.drill_point_mm(loads)
    for k in range(len(values)):
        for step in (len(loads[k]) // 2, len(loads[k]) - 1):
            F, T = loads[k, step]
            u = fs.solve(model.patch.force(F, T))
            direct = np.linalg.norm(u.reshape(-1, 3), axis=1).max()
            assert fast[k, step] == pytest.approx(direct, rel=1e-9)
            assert fast_point[k, step] == pytest.approx(np.linalg.norm(model.patch.mean @ u), rel=1e-9)
    fs.factor.close()


def test_the_envelope_is_exact_for_any_load_direction(base):
    from femstudy.uncertainty.response import Envelope

    femur, _ = base
    rng = np.random.default_rng(7)
    loads = rng.uniform(0, 1, (200, 2)) * [50.0, 300.0]
    envelope = Envelope.of(femur.units, loads)
    assert np.array_equal(envelope.max_deflection_mm(loads), femur.units.max_deflection_mm(loads))


def test_the_reduced_basis_is_within_its_bound_of_direct_solves(base):
    from femstudy.uncertainty.reduced import RTOL, StiffnessPoint

    femur, unit = base
    bases = femur.basis
    family = bases.family
    assert len(bases.bases) >= 2  # the design visits several clamped lengths
    trained = [StiffnessPoint.of(x, 20.0) for x in femur.values(unit)]
    for p in trained[:3] + [StiffnessPoint(0.8, 2.5, trained[0].clamp_length_mm)]:
        fields, error, energy, point = bases.evaluate(p)
        exact = family.solve(p)
        e = fields - exact
        K = (p.cortical * family.K_c + p.cancellous * family.K_s)
        true_energy_error = np.sqrt(np.einsum("ij,ij->j", e, K @ e))
        assert np.all(true_energy_error <= error * (1 + 1e-6) + 1e-14), (true_energy_error, error)
        drill = np.linalg.norm(family.drill_point @ e, axis=0)
        assert np.all(drill <= point * error * (1 + 1e-6) + 1e-14)
        if p in trained:  # a training point passes its check
            assert np.all(error <= RTOL * energy)
        # the clamped DOFs of that length stay fixed
        assert np.abs(fields[family.constraints(p.clamp_length_mm)[1].fixed]).max() == 0.0


def test_stiffer_bone_deflects_less_and_the_nominal_sample_is_the_study(base):
    from femstudy.uncertainty.femur import evaluate_samples
    from femstudy.uncertainty.inputs import nominal_values

    femur, _ = base
    nominal = nominal_values(femur.case, femur.loading.depth_mm)
    stiff = {**nominal, "cortical_modulus_factor": 1.2, "cancellous_modulus_factor": 1.2}
    out = evaluate_samples(femur, [nominal, stiff], [False, False])
    assert out["max_deflection_mm"][1] == pytest.approx(out["max_deflection_mm"][0] / 1.2, rel=1e-3)
    # the nominal sample is the study's quasi-static response to its loads
    F, T = femur.loading.dynamic.thrust_N, femur.loading.dynamic.torque_Nmm
    reference = femur.units.max_deflection_mm(np.column_stack([F, T])).max()
    assert out["max_deflection_mm"][0] == pytest.approx(reference, rel=1e-3)
    assert out["energy_error_bound"][0] <= 1e-3 and out["solved_directly"] == [0.0, 0.0]


def test_a_killed_run_resumes_without_recomputing_and_gives_the_same_numbers(tmp_path, mesh_cache):
    from femstudy.uncertainty.run import run_uncertainty

    case = coarse_case(application="hole", samples=40)
    common = dict(inputs=("mu_f_factor", "cutting_force_factor", "cortical_modulus_factor"), hole_samples=2,
                  workers=1, cache_dir=mesh_cache)
    first = run_uncertainty([case], tmp_path / "a", **common)
    points = sorted((tmp_path / "a" / "points").glob("uncertainty-samples-*.json"))
    assert len(points) >= 2
    points[-1].unlink()  # as if killed before the last point finished
    kept = {p.name: p.stat().st_mtime_ns for p in points[:-1]}
    again = run_uncertainty([case], tmp_path / "a", **common)
    assert {p.name: p.stat().st_mtime_ns for p in points[:-1]} == kept  # finished points not recomputed
    for column in ("max_deflection_mm", "governing_margin", "hole_von_mises_MPa", "cortical_modulus_factor"):
        assert np.array_equal(first.femurs[0].samples[column], again.femurs[0].samples[column], equal_nan=True)
    doc = json.loads((tmp_path / "a" / "uncertainty.json").read_text())
    summary = doc["femurs"][0]["summary"]
    assert summary["hole_von_mises_MPa"]["n"] == 2 and summary["max_deflection_mm"]["n"] == 40
    assert summary["max_deflection_mm"]["p5"] < summary["max_deflection_mm"]["p50"] < summary["max_deflection_mm"]["p95"]
    lines = (tmp_path / "a" / "uncertainty.csv").read_text().splitlines()
    assert len(lines) == 41 and "max_deflection_mm" in lines[0]
    assert "Spearman" in (tmp_path / "a" / "report.md").read_text()
    assert (tmp_path / "a" / "uncertainty-unc-distributions.png").stat().st_size > 10_000


def test_a_local_cluster_gives_the_numbers_of_one_process(tmp_path, mesh_cache):
    pytest.importorskip("dask.distributed")
    from femstudy.uncertainty.run import run_uncertainty

    case = coarse_case(samples=16)
    common = dict(method="sobol", inputs=("mu_w_factor", "feed_mm_s", "depth_mm"), hole_samples=0,
                  cache_dir=mesh_cache)
    serial = run_uncertainty([case], tmp_path / "serial", workers=1, **common)
    dask = run_uncertainty([case], tmp_path / "dask", workers=2, memory_limit=3e9, **common)
    assert dask.execution["scheduler"] == "LocalCluster"
    assert len(serial.femurs[0].unit) == 16 * 5
    for column in ("max_deflection_mm", "drill_point_deflection_mm", "depth_mm"):
        assert np.allclose(serial.femurs[0].samples[column], dask.femurs[0].samples[column], rtol=1e-9, atol=0)
    sens = dask.femurs[0].sensitivity["max_deflection_mm"]
    assert set(sens) == {"mu_w_factor", "feed_mm_s", "depth_mm"} and all("ST_conf" in s for s in sens.values())
