"""Synthetic recordings: the load model underneath, each effect exactly as documented, determinism."""

import csv
import time
from dataclasses import replace

import numpy as np
import pytest

from conftest import assert_clean_failure, run_cli
from femstudy.drilling.friction import load_bone_set
from femstudy.drilling.history import DrillingConditions, evaluate
from femstudy.recordings import (Effects, FeedPulsation, Noise, SensorDrift, SpindleRipple, ThermalSoftening,
                                 read_recording, synthesize)
from femstudy.recordings.dataset import dataset_recordings

CLEAN = Effects.none()


def test_clean_recording_is_the_load_model_shifted_to_contact():
    rec = synthesize(1.5, 1250, cortex_mm=7.0, effects=CLEAN, approach_s=1.0)
    m = rec.metadata
    bone = replace(load_bone_set("bovine"), u1_MPa=m["u1_MPa"], u2_MPa=m["u2_MPa"])
    cond = DrillingConditions(1.5, 1250, 7.0, bone, friction_override=(m["true_mu_f"], m["true_mu_w"]))
    cutting = rec.time_s < m["true_retraction_s"]
    model = evaluate("clogging", cond, rec.time_s[cutting] - 1.0)
    np.testing.assert_allclose(rec.thrust_N[cutting], model.thrust_N, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(rec.torque_Nmm[cutting], model.torque_Nmm, rtol=1e-9, atol=1e-9)
    assert m["true_breakthrough_s"] == pytest.approx(1.0 + 7.0 / 1.5, abs=1e-3)
    assert m["true_full_engagement_s"] == pytest.approx(1.0 + 1.35 / 1.5, abs=1e-3)
    # the friction is the bovine power law at (f, N); the loads vanish one revolution after the stop
    assert (m["true_mu_f"], m["true_mu_w"]) == pytest.approx(cond.bone.friction(1.5, 1250))
    assert np.all(rec.thrust_N[rec.time_s > m["true_retraction_s"] + 60 / 1250] == 0)


def test_same_seed_same_recording_other_seed_other_noise():
    a, b, c = synthesize(seed=7), synthesize(seed=7), synthesize(seed=8)
    np.testing.assert_array_equal(a.thrust_N, b.thrust_N)
    assert not np.array_equal(a.thrust_N, c.thrust_N)


def test_drift_and_noise_are_added_over_the_whole_recording():
    drift = SensorDrift(thrust_N_per_s=0.1, torque_Nmm_per_s=-0.3, thrust_offset_N=1.0, torque_offset_Nmm=2.0)
    base = synthesize(effects=CLEAN)
    drifted = synthesize(effects=Effects(None, None, None, drift, None))
    np.testing.assert_allclose(drifted.thrust_N - base.thrust_N, 1.0 + 0.1 * base.time_s, atol=1e-12)
    np.testing.assert_allclose(drifted.torque_Nmm - base.torque_Nmm, 2.0 - 0.3 * base.time_s, atol=1e-12)
    noisy = synthesize(effects=Effects(Noise(0.4, 1.2), None, None, None, None))
    assert np.std(noisy.thrust_N - base.thrust_N) == pytest.approx(0.4, rel=0.05)
    assert np.std(noisy.torque_Nmm - base.torque_Nmm) == pytest.approx(1.2, rel=0.05)


def test_spindle_ripple_is_at_the_spindle_frequency():
    rec = synthesize(1.5, 1200, effects=Effects(None, SpindleRipple(0.1), None, None, None), sample_rate_hz=1000)
    m = rec.metadata
    cut = (rec.time_s > m["true_full_engagement_s"]) & (rec.time_s < m["true_breakthrough_s"])
    x = np.diff(rec.thrust_N[cut])  # differencing removes the slow trend
    freq = np.fft.rfftfreq(x.size, 1e-3)[np.argmax(np.abs(np.fft.rfft(x)))]
    assert freq == pytest.approx(1200 / 60, abs=0.5)
    assert m["ripple_fraction"] == 0.1


def test_feed_pulsation_modulates_depth_and_load_and_keeps_the_mean_feed():
    p = FeedPulsation(amplitude=0.3, frequency_hz=0.7, phase_rad=0.4)
    rec = synthesize(1.5, 1500, effects=Effects(None, None, p, None, None), depth_column=True)
    clean = synthesize(1.5, 1500, effects=CLEAN)
    m = rec.metadata
    t = rec.time_s
    during = (t > m["true_contact_s"] + 0.01) & (t < m["true_retraction_s"] - 0.01)
    speed = np.gradient(rec.depth_mm, t)[during]
    expected = 1.5 * (1 + 0.3 * np.sin(2 * np.pi * 0.7 * t[during] + 0.4))
    np.testing.assert_allclose(speed, expected, rtol=2e-3)
    # the breakthrough moves by less than the pulsation's depth excursion A f/(2π f_p) / f
    shift = abs(m["true_breakthrough_s"] - clean.metadata["true_breakthrough_s"])
    assert shift <= 0.3 / (2 * np.pi * 0.7) * 2 + 1e-3
    assert m["pulsation_frequency_hz"] == 0.7 and "feed_pulsation" in m["effects"]


def test_thermal_softening_decays_the_load_with_time_in_contact():
    soft = ThermalSoftening(fraction=0.3, time_constant_s=1.5)
    rec = synthesize(effects=Effects(None, None, None, None, soft))
    clean = synthesize(effects=CLEAN)
    t, t0 = rec.time_s, rec.metadata["true_contact_s"]
    inside = (t > t0) & (t < rec.metadata["true_breakthrough_s"])
    np.testing.assert_allclose(rec.thrust_N[inside] / clean.thrust_N[inside],
                               1 - 0.3 * (1 - np.exp(-(t[inside] - t0) / 1.5)), rtol=1e-9)
    assert rec.metadata["softening_time_constant_s"] == 1.5


def test_cut_ending_by_retraction_inside_the_cortex():
    rec = synthesize(cortex_mm=6.0, stop_depth_mm=4.0, effects=CLEAN)
    assert "true_breakthrough_s" not in rec.metadata
    assert rec.metadata["true_retraction_s"] == pytest.approx(2.0 + 4.0 / 1.5, abs=1e-3)


def test_allotta_model_has_no_clogging_rise():
    rec = synthesize(model="allotta", effects=CLEAN)
    m = rec.metadata
    cut = (rec.time_s > m["true_full_engagement_s"]) & (rec.time_s < m["true_breakthrough_s"])
    np.testing.assert_allclose(rec.thrust_N[cut], m["true_initial_force_N"], rtol=1e-9)


def test_a_twenty_second_recording_is_fast():
    start = time.perf_counter()
    for seed in range(10):
        synthesize(1.0, 1000, cortex_mm=12.0, approach_s=4.0, tail_s=3.0, seed=seed)
    per_run = (time.perf_counter() - start) / 10
    assert per_run < 0.1  # about 5 ms on the development machine


def test_dataset_spreads_friction_like_appendix_b_and_plants_outliers():
    runs = dataset_recordings(replicates=10, seed=1)
    calib = [r for p, r in runs if p.startswith("calibration/")]
    assert len(calib) == 50 and len(runs) == 54
    outliers = [r for r in calib if r.metadata["outlier"]]
    assert len(outliers) == 3 and len({(r.feed_mm_s, r.spindle_rpm) for r in outliers}) == 3
    normal = [r.metadata for r in calib if not r.metadata["outlier"]]
    ln_p = np.log([m["true_mu_f"] / m["condition_mu_f"] for m in normal])
    assert 0.12 < np.std(ln_p) < 0.22
    ln_f = np.log([m["true_initial_force_N"] for m in normal if m["feed_mm_s"] == 1.0])
    assert 0.07 < np.std(ln_f) < 0.25


def test_cli_writes_a_readable_recording_and_a_dataset(tmp_path):
    out = tmp_path / "rec.csv"
    proc = run_cli("synth", "--out", str(out), "--feed", "2", "--rpm", "1000", "--clean", "--drift-N-per-s",
                   "-0.1", "--torque-unit", "Nm", "--seed", "3")
    assert proc.returncode == 0, proc.stderr
    rec = read_recording(out)
    assert rec.metadata["effects"] == ["sensor_drift"] and rec.metadata["drift_thrust_N_per_s"] == -0.1
    assert rec.metadata["seed"] == 3 and rec.spindle_rpm == 1000
    proc = run_cli("synth", "--dataset", str(tmp_path / "ds"), "--replicates", "2", "--quiet")
    assert proc.returncode == 0, proc.stderr
    truth = list(csv.DictReader((tmp_path / "ds" / "truth.csv").open()))
    assert len(truth) == 14 and len(list((tmp_path / "ds" / "calibration").glob("*.csv"))) == 10
    assert (tmp_path / "ds" / "generating_bone_set.toml").is_file()


@pytest.mark.parametrize("args, message", [
    (["--pulsation", "1.5"], "feed pulsation amplitude must lie in [0, 1)"),
    (["--ripple", "-0.1"], "--ripple must be >= 0"),
    (["--feed", "0"], "argument --feed: 0 mm/s is out of range: expected at least 0.01"),
    (["--rate-hz", "50"], "argument --rate-hz: 50 Hz is out of range: expected at least 100 and at most 10000 Hz"),
    (["--bone", "goat"], "unknown bone coefficient set 'goat'"),
])
def test_cli_bad_options_exit_2_and_write_nothing(tmp_path, args, message):
    out = tmp_path / "rec.csv"
    proc = run_cli("synth", "--out", str(out), *args)
    assert proc.returncode == 2
    assert_clean_failure(proc, message)
    assert not out.exists() and not list(tmp_path.iterdir())
