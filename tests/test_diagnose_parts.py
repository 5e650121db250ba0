"""The pieces of the diagnosis: noise level, smoothing operator, forward model, alignment, mismatch location."""

import math

import numpy as np
import pytest

from femstudy.diagnosis.band import STEP_SIGMAS, make_band, white_noise_sigma
from femstudy.diagnosis.baseline import ModelSimulation, TraceSimulation
from femstudy.diagnosis.catalogue import Variant
from femstudy.diagnosis.locate import mismatch_intervals
from femstudy.diagnosis.model import Spec, evaluate, layout
from femstudy.diagnosis.prepare import align, smoothed as build_problem
from femstudy.drilling.history import DrillingConditions
from femstudy.recordings import Effects, FeedPulsation, Noise, SensorDrift, SpindleRipple, synthesize


@pytest.mark.parametrize("rate, n", [(1000, 20000), (200, 2000)])
def test_white_noise_level_is_unbiased_within_three_percent(rate, n):
    rng = np.random.default_rng(1)
    t = np.arange(n) / rate
    estimates = [white_noise_sigma(t, rng.normal(0, 0.7, n)) for _ in range(10)]
    assert np.mean(estimates) == pytest.approx(0.7, rel=0.03)


def test_noise_level_ignores_spindle_ripple_and_the_cut():
    rec = synthesize(1.5, 1500, effects=Effects(Noise(0.4, 1.3), SpindleRipple(0.08), None, None, None), seed=2)
    clean = synthesize(1.5, 1500, effects=Effects.none())
    # a ripple of 8 % of ~35 N (2.8 N) is seven times the noise, yet the level is the noise's
    assert white_noise_sigma(rec.time_s, rec.thrust_N - clean.thrust_N) == pytest.approx(0.4, rel=0.05)
    assert white_noise_sigma(rec.time_s, rec.torque_Nmm - clean.torque_Nmm) == pytest.approx(1.3, rel=0.05)


def test_a_residual_without_noise_has_level_zero_not_nan():
    """A simulation that matches a noise-free recording exactly leaves a zero residual: its
    spectrum is flat zero, every bin of it 'a line'; the level is 0 (the noise floor then
    applies), not the NaN of an empty mean."""
    t = np.arange(4000) / 1000
    assert white_noise_sigma(t, np.zeros(t.size)) == 0.0


def test_smoothing_is_the_same_on_recording_samples_and_on_the_model_grid():
    """The same continuous kernel on a 1 kHz recording and a ~85 Hz model grid: a clean
    recording and its own model, smoothed each way, agree to under 0.2 noise units, and the
    spindle ripple is gone."""
    for rate in (1000.0, 200.0):
        rec = synthesize(1.5, 1500, effects=Effects(None, SpindleRipple(0.05), None, None, None), sample_rate_hz=rate)
        sim = synthesize(1.5, 1500, effects=Effects.none(), sample_rate_hz=333)
        band = make_band(rec.time_s, 1500, rec.time_s[0], rec.time_s[-1])
        on_samples = band.smooth(rec.thrust_N)
        on_grid = band.smooth_model(np.interp(band.t_model, sim.time_s, sim.thrust_N))
        sigma = 0.3 * band.noise_gain  # smoothed noise of a 0.3 N sensor
        assert np.max(np.abs(on_samples - on_grid) / sigma) < 0.2
    assert band.correlation == pytest.approx(math.exp(-STEP_SIGMAS ** 2 / 4))


def test_forward_model_reproduces_a_pulsed_feed_at_the_true_parameters():
    """A sine-pulsed feed against an Allotta trace (load × (1 + m) and the depth's lead ∫m): the
    model on its grid equals the synthetic recording to 2 mN of 30 N (the kinks of the entry are
    interpolated on the model grid), except within a revolution of the stop, where the two resolve
    the fall differently."""
    A, f_p, phase = 0.3, 0.7, 1.1
    for stop in (None, 4.0):  # through the cortex, and retraction inside it
        effects = Effects(None, None, FeedPulsation(A, f_p, phase), None, None)
        rec = synthesize(1.5, 1500, model="allotta", effects=effects, stop_depth_mm=stop)
        sim = synthesize(1.5, 1500, model="allotta", effects=Effects.none(), stop_depth_mm=stop)
        problem, _ = build_problem(rec, TraceSimulation.from_recording(sim, 1500), 6.0)
        variant = Variant((("frequency_hz", f_p), ("sweep", 0.0), ("harmonics", 1)))
        spec = Spec((("feed_pulsation", variant),))
        lay = layout(problem, spec)
        theta = lay.start.copy()
        # the generator's m = A sin(2π f t + φ), written on the model's phase 2π f (t − t_m)
        centre = problem.contact_t + problem.cut_s / 2
        total = 2 * math.pi * f_p * centre + phase
        theta[lay.index("feed_pulsation.a1")] = A * math.cos(total)
        theta[lay.index("feed_pulsation.b1")] = A * math.sin(total)
        grid = evaluate(problem, spec, lay, theta).grid[0]
        truth = np.interp(problem.band.t_model, rec.time_s, rec.thrust_N)
        away = np.abs(problem.band.t_model - rec.metadata["true_retraction_s"]) > 0.05
        assert np.max(np.abs(grid - truth)[away]) < 2e-3


def test_trace_contact_and_stop_are_read_from_the_trace():
    sim = synthesize(1.2, 1200, effects=Effects.none(), sample_rate_hz=250, approach_s=1.3)
    trace = TraceSimulation.from_recording(sim, 1200)
    assert trace.contact_s == pytest.approx(1.3, abs=1e-9)  # the linear entry ramp extrapolated to zero
    # the stop is where the final fall starts, read to the trace's sample (4 ms)
    assert trace.stop_s == pytest.approx(sim.metadata["true_retraction_s"], abs=1 / 250)
    assert trace.span() == (-math.inf, math.inf)  # unloaded at both ends: continued by zero


def test_trace_that_ends_loaded_limits_the_comparison_to_its_span():
    rec = synthesize(1.5, 1500, effects=Effects(Noise(0.3, 1.0), None, None, None, None))
    sim = synthesize(1.5, 1500, effects=Effects.none())
    cut = sim.time_s < 5.0  # the simulation stops in mid-cortex, loaded
    trace = TraceSimulation(sim.time_s[cut], sim.thrust_N[cut], sim.torque_Nmm[cut], 1500)
    assert trace.span() == (-math.inf, pytest.approx(sim.time_s[cut][-1]))
    problem, notes = build_problem(rec, trace, 6.0)
    assert problem.band.t_dec[-1] <= 5.0 and "compared over" in notes[0]


def test_a_trace_that_starts_at_contact_already_loaded_is_compared_from_its_start():
    """A simulation written from the instant of contact carries load in its first sample: it is
    read as starting at contact (in air before), not refused for lacking its contact."""
    rec = synthesize(1.5, 1500, effects=Effects(Noise(0.3, 1.0), None, None, None, None), approach_s=1.0)
    sim = synthesize(1.5, 1500, effects=Effects.none(), approach_s=1.0)
    after = sim.time_s >= 1.2  # the first sample already loaded
    trace = TraceSimulation(sim.time_s[after], sim.thrust_N[after], sim.torque_Nmm[after], 1500)
    assert trace.thrust_N[0] > 0 and trace.zero_before
    assert trace.contact_s == pytest.approx(sim.time_s[after][0])
    problem, notes = build_problem(rec, trace, 6.0)
    assert problem.band.t_dec[0] <= trace.contact_s <= problem.band.t_dec[-1]


def test_a_simulation_outside_the_recording_is_refused():
    from femstudy.errors import UserError

    rec = synthesize(1.5, 1500, effects=Effects(Noise(0.3, 1.0), None, None, None, None))
    sim = synthesize(1.5, 1500, effects=Effects.none())
    late = TraceSimulation(sim.time_s + 100.0, sim.thrust_N, sim.torque_Nmm, 1500)
    with pytest.raises(UserError, match="does not overlap recording"):
        build_problem(rec, late, 6.0)


def test_alignment_finds_a_clock_offset_and_tare_despite_missing_clogging():
    """Clogging adds up to 130 % after full engagement; the robust alignment still reads the
    offset from the entry ramp and the tare from the unloaded stretches."""
    effects = Effects(Noise(0.3, 1.0), None, None, SensorDrift(0.0, 0.0, 0.8, 3.0), None)
    rec = synthesize(1.5, 1500, effects=effects)
    sim = synthesize(1.5, 1500, model="allotta", effects=Effects.none(), approach_s=1.9)  # contact 0.1 s early
    problem, _ = build_problem(rec, TraceSimulation.from_recording(sim, 1500), 6.0)
    alignment = align(problem)
    assert alignment.shift_s == pytest.approx(0.1, abs=0.005)
    assert alignment.tares[0] == pytest.approx(0.8, abs=0.05)
    assert alignment.tares[1] == pytest.approx(3.0, abs=0.2)


def test_alignment_holds_under_a_strong_drift():
    """A zero drifting by 2 N/s must not move the clock: the alignment's cost is taken about a
    straight line through the unloaded instants."""
    effects = Effects(Noise(0.3, 1.0), None, None, SensorDrift(-2.0, -10.0), None)
    rec = synthesize(1.5, 1500, effects=effects)
    sim = synthesize(1.5, 1500, model="allotta", effects=Effects.none(), approach_s=1.9)
    problem, _ = build_problem(rec, TraceSimulation.from_recording(sim, 1500), 6.0)
    assert align(problem).shift_s == pytest.approx(0.1, abs=0.01)


def test_load_model_simulation_is_the_load_model_from_contact_to_stop():
    cond = DrillingConditions(1.5, 1500, 6.0, friction_override=(0.2, 0.58))
    rec = synthesize(1.5, 1500, mu_f=0.2, mu_w=0.58, effects=Effects.none(), approach_s=2.0)
    sim = ModelSimulation("clogging", cond, contact_s=2.0, stop_depth_mm=8.0)
    F, T = sim.loads(rec.time_s)
    np.testing.assert_allclose(F, rec.thrust_N, atol=2e-3 * rec.thrust_N.max())
    np.testing.assert_allclose(T, rec.torque_Nmm, atol=2e-3 * rec.torque_Nmm.max())


def test_mismatch_intervals_silent_on_noise_and_located_on_a_bump():
    rng = np.random.default_rng(0)
    t = np.arange(200) * 0.12
    assert mismatch_intervals(t, rng.normal(size=t.size), 0.9, "thrust_N") == []
    z = rng.normal(size=t.size)
    z[(t > 8.0) & (t < 10.0)] += 12.0
    (interval,) = mismatch_intervals(t, z, 0.9, "thrust_N")
    assert interval["start_s"] == pytest.approx(8.0, abs=0.15) and interval["end_s"] == pytest.approx(10.0, abs=0.15)
    assert interval["significance"] > 50 and interval["channel"] == "thrust_N"
    z[50] = 1e4  # far beyond the floating-point range of the exact tail: still a finite significance
    assert all(math.isfinite(i["significance"]) for i in mismatch_intervals(t, z, 0.9, "thrust_N"))


def test_mis_scaled_simulation_is_a_calibration_not_missing_physics(monkeypatch):
    """A simulation with a 5 % low cortical cutting energy u1: located as a mismatch, explained
    by the scale on the simulated loads (calibration), no mechanism reported. The rescaled
    family costs one fit per subset, in the variants the one search chose."""
    import importlib

    from femstudy.diagnosis import diagnose, search

    diagnose_module = importlib.import_module("femstudy.diagnosis.diagnose")  # the package's name is the function
    searched, refitted = [], []
    monkeypatch.setattr(diagnose_module, "fit_all", lambda *a, **k: searched.append(search.fit_all(*a, **k)) or searched[-1])
    monkeypatch.setattr(diagnose_module, "refit_all", lambda *a, **k: refitted.append(search.refit_all(*a, **k)) or refitted[-1])
    rec = synthesize(1.5, 1500, effects=Effects(Noise(0.3, 1.0), SpindleRipple(0.05), None, None, None), seed=4)
    sim = synthesize(1.5, 1500, u1_MPa=0.95 * 448.5, effects=Effects.none(), sample_rate_hz=500)
    d = diagnose(rec, TraceSimulation.from_recording(sim, 1500), 6.0)
    js = d.to_json()
    assert js["missing_physics"] == [] and js["mismatch"]
    assert js["calibration"]["thrust_N_scale"] == pytest.approx(1 / 0.95, rel=0.01)
    assert js["calibration"]["torque_Nmm_scale"] == pytest.approx(1 / 0.95, rel=0.01)
    assert len(searched) == 1 and len(refitted) == 1
    assert {s: f.spec for s, f in refitted[0].items()} == {s: f.spec for s, f in searched[0].items()}


def test_model_derivatives_match_finite_differences_in_every_coefficient():
    """All four mechanisms together (clogging with its after-breakthrough columns, a drift, a
    softening that spares the packed chips' friction, a pulsed feed): the derivatives the fits use
    equal central differences of the model to 1e-6 of the column's size in every parameter that
    does not move the clock (the shift, the pulsation's phase-setting coefficients and frequency
    move it through the simulated loads' slopes, which are differenced on the model grid)."""
    from femstudy.diagnosis.catalogue import MECHANISMS

    rec = synthesize(1.5, 1500, model="allotta", effects=Effects.none(), seed=3)
    sim = synthesize(1.5, 1500, model="allotta", effects=Effects.none())
    problem, _ = build_problem(rec, TraceSimulation.from_recording(sim, 1500), 6.0)
    chosen = [(n, MECHANISMS[n].variants(problem, None, None)[-1]) for n in ("chip_clogging", "sensor_drift", "thermal_softening")]
    spec = Spec(tuple(chosen) + (("feed_pulsation", Variant((("frequency_hz", 0.7), ("sweep", 0.0), ("harmonics", 1)))),))
    lay = layout(problem, spec)
    rng = np.random.default_rng(0)
    theta = lay.start.copy()
    bounded = np.isfinite(lay.lower) & np.isfinite(lay.upper)
    theta[bounded] = lay.lower[bounded] + (lay.upper[bounded] - lay.lower[bounded]) * rng.uniform(0.3, 0.4, bounded.sum())
    theta[[k for k, n in enumerate(lay.names) if n.startswith("chip_clogging.") and "torque" not in n]] = 0.05
    J = evaluate(problem, spec, lay, theta).jacobian
    clock = {"shift_correction_s", "feed_pulsation.a1", "feed_pulsation.b1", "feed_pulsation.frequency_hz"}
    checked = 0
    for k, name in enumerate(lay.names):
        if name in clock:
            continue
        h = 1e-6 * max(1.0, abs(theta[k]))
        up, down = theta.copy(), theta.copy()
        up[k] += h
        down[k] -= h
        fd = (evaluate(problem, spec, lay, up).model - evaluate(problem, spec, lay, down).model) / (2 * h)
        assert np.max(np.abs(J[:, :, k] - fd)) <= 1e-6 * max(np.max(np.abs(fd)), 1.0), name
        checked += 1
    assert checked == len(lay.names) - len(clock)


def test_a_rescaling_that_cannot_reach_noise_is_not_refitted_and_changes_nothing(monkeypatch):
    """A 5 % low simulation and a thrust step of +30 % halfway through the cut (outside the
    catalogue): even the fullest fit with the scales stays far above noise, so the rescaled family
    is not refitted; refitting it anyway (no reach limit) gives the same diagnosis."""
    import importlib
    from dataclasses import replace

    from femstudy.diagnosis import diagnose

    diagnose_module = importlib.import_module("femstudy.diagnosis.diagnose")  # the package's name is the function

    rec = synthesize(1.5, 1500, effects=Effects(Noise(0.3, 1.0), SpindleRipple(0.05), None, None, None), seed=4)
    sim = TraceSimulation.from_recording(
        synthesize(1.5, 1500, u1_MPa=0.95 * 448.5, effects=Effects.none(), sample_rate_hz=500), 1500)
    late = (rec.time_s > rec.time_s[rec.time_s.size // 2]) & (rec.thrust_N > 0.3 * rec.thrust_N.max())
    rec = replace(rec, thrust_N=rec.thrust_N * np.where(late, 1.3, 1.0))
    said: list[str] = []
    skipped = diagnose(rec, sim, 6.0, progress=said.append).to_json()
    assert any("rescaled would still leave more than noise" in s for s in said)
    monkeypatch.setattr(diagnose_module, "RESCALED_REACH", math.inf)
    said.clear()
    searched = diagnose(rec, sim, 6.0, progress=said.append).to_json()
    assert any("refitted with the simulated loads rescaled: not better" in s for s in said)
    for key in ("missing_physics", "unexplained", "calibration", "fit"):
        assert skipped[key] == searched[key]


def test_fits_spread_over_worker_processes_equal_the_fits_made_one_by_one():
    """Every subset's fit made in forked workers (two) is the one made in the caller: the same
    spec and, to the last digit, the same parameters, χ² and model; its evaluation, rebuilt in
    the caller, gives that model again."""
    from femstudy.diagnosis.diagnose import robust_baseline
    from femstudy.diagnosis.fitpool import FitPool
    from femstudy.diagnosis.search import fit_all
    from femstudy.lanes import can_fork

    if not can_fork():
        pytest.skip("worker processes are forked on Linux with two or more cores only")
    rec = synthesize(1.5, 1500, effects=Effects(Noise(0.3, 1.0), SpindleRipple(0.05), None, SensorDrift(0.4, 1.5), None),
                     seed=5)
    sim = synthesize(1.5, 1500, effects=Effects.none())
    problem, _ = build_problem(rec, TraceSimulation.from_recording(sim, 1500), 6.0)
    with FitPool(problem, workers=2) as pool:
        assert pool.forked
    baseline = robust_baseline(problem, align(problem))
    alone, spread = fit_all(problem, baseline, workers=1), fit_all(problem, baseline, workers=2)
    assert alone.keys() == spread.keys() and len(alone) == 2 ** 4
    for subset, f in alone.items():
        g = spread[subset]
        assert f.spec == g.spec, subset
        assert np.array_equal(f.theta, g.theta) and np.array_equal(f.chi2, g.chi2) and np.array_equal(f.model, g.model)
        assert f.n_params == g.n_params
        assert np.array_equal(g.evaluation.model, g.model)


def test_clock_search_smoothing_is_scipys_gaussian_filter_to_round_off():
    from scipy import ndimage

    from femstudy.diagnosis.timing import gaussian_rows

    rng = np.random.default_rng(3)
    y = np.cumsum(rng.normal(size=(7, 400)), axis=1)
    for sigma in (1.0, 10.0, 37.5):
        expected = ndimage.gaussian_filter1d(y, sigma, axis=-1, mode="nearest")
        assert np.max(np.abs(gaussian_rows(y, sigma) - expected)) <= 1e-12 * np.max(np.abs(y))
    assert np.allclose(gaussian_rows(y[0], 10.0), ndimage.gaussian_filter1d(y[0], 10.0, mode="nearest"), rtol=0,
                       atol=1e-12 * np.max(np.abs(y)))
    assert gaussian_rows(np.zeros((3, 0)), 10.0).shape == ndimage.gaussian_filter1d(np.zeros((3, 0)), 10.0).shape


def test_the_air_step_search_ranks_each_index_as_a_least_squares_fit_would():
    from femstudy.diagnosis.air import _step_sse

    rng = np.random.default_rng(4)
    for n in (40, 333, 2000):
        u = np.sort(rng.uniform(0, 3, n))
        s = 2 + 0.3 * u + rng.normal(0, 1, n) + 5.0 * (np.arange(n) >= n // 3)
        ks = np.arange(5, n - 5, 2)
        fitted = []
        for k in ks:
            A = np.column_stack([np.ones(n), u, (np.arange(n) >= k).astype(float)])
            c, *_ = np.linalg.lstsq(A, s, rcond=None)
            fitted.append(float(np.sum((s - A @ c) ** 2)))
        assert np.allclose(_step_sse(u, s, ks), fitted, rtol=1e-10, atol=0)
        assert abs(int(ks[np.argmin(_step_sse(u, s, ks))]) - n // 3) <= 2
