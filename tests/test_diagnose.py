"""``femstudy diagnose`` on concealed synthetic cases: the right mechanisms, the right sizes, silence
when nothing is missing (one fixed-seed case per class of bench/synthetic_cases.py, femstudy's own
generator, whose forms are the thesis's; four seeds for the class with three mechanisms at once)."""

import math

import pytest

from bench.synthetic_cases import CLASSES, make_case
from femstudy.diagnosis import diagnose
from femstudy.diagnosis.baseline import TraceSimulation

_cache = {}


def diagnosed(kind: str, seed: int, torque: bool = True):
    key = (kind, seed, torque)
    if key not in _cache:
        case = make_case(kind, seed, torque=torque)
        rec = case.recording
        sim = TraceSimulation.from_recording(case.simulation, rec.spindle_rpm)
        _cache[key] = case, diagnose(rec, sim, float(rec.metadata["cortex_mm"]))
    return _cache[key]


def found(d) -> dict:
    return {m["mechanism"]: m for m in d.to_json()["missing_physics"]}


THREE = "pulse_feed_clogging_softening"


def assert_fit_gains(d) -> None:
    """A named model fits the cut far better than the simulation, and the mismatch shows."""
    fit = d.to_json()["fit"]
    assert fit["improved"]["r2"] > 0.995 and fit["improved"]["rmse"] < 0.5 * fit["baseline"]["rmse"]
    assert d.mismatch, "a missing mechanism must show as a mismatch interval"


@pytest.mark.parametrize("kind", sorted(set(CLASSES) - {THREE}))
def test_each_concealed_class_is_diagnosed_exactly(kind):
    case, d = diagnosed(kind, 7)
    assert d.subset == case.truth, (d.to_json()["selection"]["not_selected"], d.to_json()["selection"]["bic"])
    assert d.residual_check.consistent_with_noise, d.residual_check
    if case.truth:
        assert_fit_gains(d)
        # calibrated confidence (femstudy.diagnosis.confidence, fitted on formbench tuning seeds 1, 4, 5, 10, 11)
        assert all(m.confidence > 0.75 for m in d.mechanisms)
    else:
        assert d.mechanisms == () and d.mismatch == () and d.unexplained == ()


def test_three_mechanisms_at_once_are_diagnosed_exactly_in_most_cases():
    # clogging, a feed pulsation and softening together, three flexible forms at once: exact on
    # 12 of seeds 0-19 (16 before the noise model's slowest part was extrapolated as 1/f, 14
    # before a softening had to take less than 75 % of the loads, both 2026-11-27, both of which
    # gained elsewhere: docs/diagnosis.md, Benchmarks); of seeds 0-3, all but 2 (its fit keeps the
    # clogging's torque gain at its start: docs/diagnosis.md, 'Tried and reverted').
    # Their residual is not at the noise (chi2/dof 0.9-12.7 over seeds 0-6, before as after), so
    # the confidences are lower than for one mechanism (0.62-0.99) but above even odds
    exact = 0
    for seed in range(4):
        case, d = diagnosed(THREE, seed)
        if d.subset == case.truth:
            exact += 1
            assert_fit_gains(d)
            assert all(m.confidence > 0.5 for m in d.mechanisms)
    assert exact >= 3


def test_clogging_under_larger_pulsation_recovers_growth_friction_and_pulsation():
    case, d = diagnosed("clogging_under_pulsation", 7)
    t = case.true
    assert t["amplitude"] > t["rise"]  # the pulsation swings the load more than clogging raises it
    clog, puls = found(d)["chip_clogging"]["parameters"], found(d)["feed_pulsation"]["parameters"]
    # the flexible rise read with the thesis's law gives its growth exponent and frictions back
    assert clog["growth_exponent_per_diameter"] == pytest.approx(t["growth_exponent"], rel=0.05)
    assert clog["rise_at_breakthrough"] == pytest.approx(t["rise"], rel=0.05)
    assert clog["mu_w_source"].startswith("the torque gain")
    assert clog["implied_mu_f"] == pytest.approx(t["mu_f"], rel=0.05)
    assert clog["mu_w_used"] == pytest.approx(t["mu_w"], rel=0.05)
    assert puls["amplitude"] == pytest.approx(t["amplitude"], rel=0.05)
    assert puls["frequency_hz"] == pytest.approx(t["frequency_hz"], rel=0.02)


def test_clogging_hidden_by_opposite_drift_recovers_both():
    case, d = diagnosed("clogging_hidden_by_drift", 7)
    t = case.true
    drift, clog = found(d)["sensor_drift"]["parameters"], found(d)["chip_clogging"]["parameters"]
    assert t["thrust_N_per_s"] < 0  # the drift pulls against the clogging rise
    assert drift["thrust_N_per_s"] == pytest.approx(t["thrust_N_per_s"], rel=0.05, abs=0.01)
    assert drift["torque_Nmm_per_s"] == pytest.approx(t["torque_Nmm_per_s"], rel=0.05, abs=0.03)
    assert clog["growth_exponent_per_diameter"] == pytest.approx(t["growth_exponent"], rel=0.05)


def test_softening_fraction_and_time_constant():
    case, d = diagnosed("softening", 7)
    p = found(d)["thermal_softening"]["parameters"]
    assert p["fraction"] == pytest.approx(case.true["fraction"], rel=0.1)
    assert p["time_constant_s"] == pytest.approx(case.true["time_constant_s"], rel=0.25)
    assert p["loss_at_end_of_cut"] == pytest.approx(case.true["loss_at_end_of_cut"], rel=0.1)


def test_drift_alone_rates():
    case, d = diagnosed("drift", 7)
    p = found(d)["sensor_drift"]["parameters"]
    assert p["thrust_N_per_s"] == pytest.approx(case.true["thrust_N_per_s"], rel=0.1, abs=0.005)
    assert p["torque_Nmm_per_s"] == pytest.approx(case.true["torque_Nmm_per_s"], rel=0.1, abs=0.02)


def test_short_cortex_clogging_growth_matches_the_bone_set():
    case, d = diagnosed("short_cortex", 7)
    assert case.recording.metadata["cortex_mm"] <= 3.0
    p = found(d)["chip_clogging"]["parameters"]
    assert p["growth_exponent_per_diameter"] == pytest.approx(case.true["growth_exponent"], rel=0.1)


def test_without_torque_clogging_is_found_on_thrust_and_mu_w_comes_from_the_bone_set():
    case, d = diagnosed("clogging_hidden_by_drift", 11, torque=False)
    assert d.problem.channels == ("thrust_N",)
    assert d.subset == case.truth
    clog = found(d)["chip_clogging"]["parameters"]
    assert "torque_gain_Nmm_per_N" not in clog and clog["mu_w_source"].startswith("the bone set")
    # μ_w is the bone set's here, which is also the generator's: μ_f follows
    assert clog["implied_mu_f"] == pytest.approx(case.true["mu_f"], rel=0.05)
    assert set(d.to_json()["fit"]["channels"]) == {"thrust_N"}


def test_json_contract_names_and_types():
    _, d = diagnosed("clogging_under_pulsation", 7)
    js = d.to_json()
    assert {"mismatch", "missing_physics", "unexplained", "fit"} <= set(js)
    for m in js["mismatch"]:
        assert set(m) >= {"start_s", "end_s", "channel", "significance"}
        assert m["channel"] in ("thrust_N", "torque_Nmm") and m["start_s"] < m["end_s"]
        assert isinstance(m["significance"], float) and math.isfinite(m["significance"])
    for m in js["missing_physics"]:
        assert m["mechanism"] in ("chip_clogging", "feed_pulsation", "sensor_drift", "thermal_softening")
        assert 0 <= m["confidence"] <= 1 and isinstance(m["parameters"], dict) and m["explanation"]
        assert all(check["passed"] for check in m["evidence"]["signatures"].values())
    for k in ("baseline", "improved"):
        assert set(js["fit"][k]) == {"r2", "r2_heldout", "rmse"}
    assert js["fit"]["improved"]["r2"] > js["fit"]["baseline"]["r2"]
    # held out, the named mechanisms still predict the cut better than the simulation alone
    assert js["fit"]["improved"]["r2_heldout"] > js["fit"]["baseline"]["r2_heldout"]
    for u in js["unexplained"]:
        assert set(u) >= {"start_s", "end_s", "channel", "description"} and u["start_s"] <= u["end_s"]


def test_a_mechanism_below_the_naming_confidence_is_dropped_and_the_verdict_decided_again(monkeypatch):
    import importlib
    from dataclasses import replace

    module = importlib.import_module("femstudy.diagnosis.diagnose")
    _, d = diagnosed("clogging_under_pulsation", 7)
    assert len(d.mechanisms) == 2 and all(m.confidence >= module.NAMING_CONFIDENCE for m in d.mechanisms)
    weakest = d.mechanisms[-1]
    threshold = weakest.confidence + 1e-6
    monkeypatch.setattr(module, "NAMING_CONFIDENCE", threshold)
    verdict, named = module.confident_verdict(d.problem, {f.subset: f for f in d.fits}, d.selection, d.baseline,
                                              d.verdict, None, workers=1)
    # the weakest goes first; the verdict is decided again, and whatever is still named clears the bar
    assert weakest.mechanism not in verdict.subset and all(n.confidence >= threshold for n in named)
    assert {n.mechanism for n in named} == verdict.subset == verdict.fit.subset
    dropped = [r for r in verdict.replaced if "more likely wrong than right" in r.reason]
    assert dropped[0].mechanism == weakest.mechanism and f"{weakest.confidence:.2f}" in dropped[0].reason
    assert len(dropped) == len(d.mechanisms) - len(named)
    # the evidence a drop rested on is kept (the JSON's selection.dropped_by_confidence), so that the
    # confidence model can be calibrated on every mechanism judged, not only on those named
    from femstudy.diagnosis.confidence import Evidence, confidence

    assert dropped[0].evidence == weakest.evidence
    assert confidence(Evidence.from_json(weakest.evidence.to_json())) == pytest.approx(
        weakest.confidence, abs=1e-3)
    judged = replace(d, verdict=verdict, mechanisms=named).to_json()["selection"]["dropped_by_confidence"]
    assert judged[weakest.mechanism]["confidence"] == pytest.approx(weakest.confidence, abs=1e-4)
    assert judged[weakest.mechanism]["evidence"] == weakest.evidence.to_json()


def test_a_held_out_refit_holds_the_coefficients_only_the_held_out_block_shows():
    """heldout.unsupported_coefficients: with every instant seen, none; with the instants where a
    clogging coefficient's column lives held out, that coefficient (and no tare or alignment)."""
    import numpy as np

    from femstudy.diagnosis import heldout

    _, d = diagnosed("clogging_under_pulsation", 7)
    p, f = d.problem, d.improved
    assert heldout.unsupported_coefficients(p, f, p.usable) == ()
    block = f.layout.blocks["chip_clogging"]
    J = f.evaluation.jacobian
    k = max(range(block.start, block.stop), key=lambda j: float(np.sum(J[:, :, j] ** 2)))
    lives = np.any(J[:, :, k] != 0, axis=0)
    held = heldout.unsupported_coefficients(p, f, p.usable & ~lives)
    assert f.layout.names[k] in held
    mechanism_names = {f.layout.names[j] for b in f.layout.blocks.values() for j in range(b.start, b.stop)}
    assert set(held) <= mechanism_names


def test_the_result_is_typed_all_the_way_down():
    """No bare dict, list or object field in the Diagnosis: dicts exist only in to_json()."""
    import dataclasses
    import typing

    from femstudy.diagnosis.result import Diagnosis

    hints = typing.get_type_hints(Diagnosis)
    for f in dataclasses.fields(Diagnosis):
        assert hints[f.name] not in (dict, list, object), f.name
        assert typing.get_origin(hints[f.name]) not in (dict, list), f.name
