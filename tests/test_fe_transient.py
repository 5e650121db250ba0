"""Newmark average acceleration in a reduced basis and by stepping: step loads, energy,
damping, the quasi-static limit, resolved vibration, memory, and a cantilever's modal solution."""

import tracemalloc

import numpy as np
import pytest

from fe_cases import R_IN, R_OUT, clamped_both_ends, end_facets, mid_slice_load, tube
from femstudy.errors import UserError
from femstudy.fe import (StepRecorder, factorize, fix_facets, point_channel, solve_modal, solve_static,
                         solve_transient, step_check)
from femstudy.fe.geometry import polygon_section, tube_mesh
from femstudy.fe import assemble, linsolve


@pytest.fixture(scope="module")
def model():
    system = tube(1, 12, 12, 2)  # 5.4k DOFs: the time integrator, not the mesh, is under test
    fs = factorize(system, clamped_both_ends(system))
    f = mid_slice_load(system, width=100.0)
    period = solve_modal(fs, k=1).period_s[0]
    return fs, f, period


def _march(fs, f, amplitudes, times, scheme="auto", **kwargs):
    """(result, load-weighted deflection f·u per step, kept fields) of one march."""
    recorder = StepRecorder([point_channel("w", f[None, :], [0, 0, 0])], len(times), keep=range(len(times)))
    result = solve_transient(fs, f[:, None], np.asarray(amplitudes, float).reshape(len(times), 1), times,
                             observer=recorder, scheme=scheme, **kwargs)
    fields = np.array([recorder.fields[n] for n in range(len(times))])
    return result, fields @ f, fields


def test_suddenly_applied_load_peaks_at_twice_static_and_oscillates_about_it(model):
    fs, f, period = model
    static = f @ solve_static(fs, f)
    times = np.arange(65) * period / 40  # 1.6 periods of the first mode, 40 steps each
    result, w, _ = _march(fs, f, np.ones(len(times)), times)
    assert result.scheme == "reduced"
    w = w / static
    assert w[0] == pytest.approx(0.0, abs=1e-12)
    # undamped step response Σ c_i (1 − cos ω_i t), c_i ≥ 0: never above 2 × static; the first
    # mode carries almost all of it, so the sampled peak reaches 2 × static within 5 %
    assert 1.95 < w.max() <= 2.0 + 1e-6
    assert (w.max() + w.min()) / 2 == pytest.approx(1.0, abs=0.03)


@pytest.mark.parametrize("scheme", ["auto", "stepping"])
def test_free_vibration_conserves_energy(model, scheme):
    fs, f, period = model
    u0 = solve_static(fs, f)
    times = np.arange(61) * period / 20
    result, _, _ = _march(fs, f, np.zeros(len(times)), times, scheme=scheme, u0=u0)
    energy = result.energies["kinetic_energy_mJ"] + result.energies["strain_energy_mJ"]
    assert energy[0] == pytest.approx(0.5 * u0 @ fs.system.K @ u0, rel=1e-9)
    # the rule conserves it exactly; what drifts is round-off (1e-6 is the tolerance asked for)
    assert np.abs(energy / energy[0] - 1).max() < 1e-6
    assert result.energies["kinetic_energy_mJ"].max() > 0.5 * energy[0]  # it really vibrates


def test_rayleigh_damping_only_dissipates(model):
    fs, f, period = model
    u0 = solve_static(fs, f)
    times = np.arange(61) * period / 20
    zeta, omega = 0.05, 2 * np.pi / period
    result, _, _ = _march(fs, f, np.zeros(len(times)), times, u0=u0, damping=(2 * zeta * omega, 0.0))
    energy = result.energies["kinetic_energy_mJ"] + result.energies["strain_energy_mJ"]
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])
    # C = αM with α = 2ζω damps the first mode by ζ: its energy decays as exp(−2ζωt); the
    # higher modes, damped less, hold a few per cent of it
    assert energy[-1] / energy[0] == pytest.approx(np.exp(-2 * zeta * omega * times[-1]), rel=0.5)


def test_thesis_time_steps_give_the_quasi_static_answer(model):
    fs, f, period = model
    times = np.linspace(0.0, 3.0, 31)  # the thesis's 0.1 s steps, thousand times the period
    ramp = np.exp(times) - 1  # a smooth, growing load from zero
    result, _, fields = _march(fs, f, ramp, times)
    check = step_check(period, result.dt_s)
    assert check.verdict == "quasi-static" and check.steps_per_period < 0.1
    assert result.scheme == "reduced" and result.n_vectors <= 4 and result.indicator <= 1e-9
    # Δt ≫ T: each step returns the static solution of its load (to ~ (T/Δt)², far below 1e-3)
    static = solve_static(fs, f)
    np.testing.assert_allclose(fields, np.outer(ramp, static), rtol=0, atol=1e-3 * np.abs(static).max() * ramp[-1])


def test_step_check_and_time_grid_errors(model):
    assert step_check(0.01, 0.0005).verdict == "resolved"
    assert step_check(0.01, 0.0005).period_elongation == pytest.approx(np.pi ** 2 / 12 * 0.05 ** 2)
    assert step_check(0.01, 0.003).verdict == "under-resolved"
    fs, _, _ = model
    with pytest.raises(UserError, match="uniform"):
        solve_transient(fs, np.zeros((fs.system.n_dofs, 1)), np.zeros((3, 1)), [0.0, 0.1, 0.3])


@pytest.mark.parametrize("damping, start", [((0.0, 0.0), "rest"), ((30.0, 1e-4), "displaced")])
def test_reduced_march_reproduces_stepping_when_steps_are_long(model, damping, start):
    """At the thesis's 0.1 s steps a few Ritz vectors carry the whole march: same fields as
    stepping to 1e-9, Rayleigh damping and a displaced start included."""
    fs, f, _ = model
    times = np.linspace(0.0, 3.0, 31)
    load = np.sin(times) ** 2
    u0 = None if start == "rest" else 0.5 * solve_static(fs, f)
    (reduced, _, a), (stepped, _, b) = (_march(fs, f, load, times, scheme=s, damping=damping, u0=u0)
                                        for s in ("auto", "stepping"))
    assert reduced.scheme == "reduced" and stepped.scheme == "stepping"
    assert reduced.n_vectors < 16 and reduced.indicator <= 1e-9
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.abs(b).max())


@pytest.mark.parametrize("load", ["step", "ramp", "oscillation"])
def test_resolved_reduced_march_is_within_its_indicator_of_stepping(model, load):
    """With 40 steps per period the reduced march resolves the vibration; its displacements
    stay within 10 × its error indicator (and 1e-3) of plain stepping."""
    fs, f, period = model
    times = np.arange(161) * period / 40
    n = np.arange(161)
    amplitudes = {"step": np.r_[0.0, np.ones(160)], "ramp": np.minimum(n / 80, 1.0),
                  "oscillation": np.sin(2 * np.pi * n / 160) ** 2}[load]
    (reduced, _, a), (stepped, _, b) = (_march(fs, f, amplitudes, times, scheme=s) for s in ("auto", "stepping"))
    assert reduced.scheme == "reduced"
    error = np.linalg.norm(a - b, axis=1).max() / np.linalg.norm(b, axis=1).max()
    assert error <= max(10 * reduced.indicator, 1e-12) and error < 1e-3


def test_reduced_march_memory_does_not_grow_with_the_step_count(model):
    """Ten times the steps cost the m × steps coordinates, not n_dofs × steps fields."""
    fs, f, period = model
    channel = [point_channel("w", f[None, :], [0, 0, 0])]

    def peak_bytes(n_steps):
        times = np.arange(n_steps) * period / 20
        tracemalloc.start()
        recorder = StepRecorder(channel, n_steps)
        solve_transient(fs, f[:, None], np.sin(times / period)[:, None] ** 2, times, observer=recorder)
        recorder.history()
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return peak

    small, large = peak_bytes(400), peak_bytes(4000)
    one_field_history = 8 * fs.system.n_dofs * 3600  # what storing the extra fields would take
    assert large - small < 0.05 * one_field_history


EULER_BERNOULLI_CANTILEVER = np.array([1.8751040687, 4.6940911330, 7.8547574382])  # β_i L


def _ramped_step(omega, t, dt):
    """Response, per unit static deflection, of an undamped oscillator to a load rising
    linearly from 0 at t = 0 to 1 at t = dt and constant after (the trapezoidal rule's reading
    of a load sampled 0, 1, 1, …): 1 − [sin ω t − sin ω (t − dt)] / (ω dt) for t ≥ dt."""
    return 1 - (np.sin(np.outer(t, omega)) - np.sin(np.outer(t - dt, omega))) / (omega * dt)


def test_cantilever_step_response_follows_its_analytic_modal_solution():
    """A slender tube clamped at one end, a tip load switched on over the first step, 400
    steps per period of the first mode (65 per period of the second bending mode). (a) The model is a cantilever: static tip deflection and first
    frequency within 1 % of Euler–Bernoulli's F L³/(3EI) and (β₁L)²√(EI/ρAL⁴). (b) The reduced
    march follows the modal solution u(t) = Σ_i φ_i φ_iᵀf / ω_i² · r(ω_i t) of the same model
    (its 20 lowest modes, the rest quasi-static) within 0.6 % of the static deflection over
    1.5 periods: the time step's own error (plain stepping is 0.42 % off, 1.1 % at 200 steps per
    period; the reduced march is within 1e-4 of stepping)."""
    length, n_around = 600.0, 16
    system = assemble(tube_mesh(length, R_OUT, R_IN, 1, n_around, 30), order=2)
    fs = factorize(system, fix_facets(system, end_facets(system, 0.0)))
    dofs = np.unique(system.dofs.get_facet_dofs(end_facets(system, length)).flatten())
    y_dofs = dofs[dofs % 3 == 1]
    f = np.zeros(system.n_dofs)
    f[y_dofs] = 1.0 / len(y_dofs)  # 1 N along y over the tip face
    tip = f[None, :]  # the mean y-displacement of the tip face's nodes
    section = polygon_section(R_OUT, R_IN, n_around)
    E, rho = 16e3, 1700e-12
    static = float(tip[0] @ solve_static(fs, f))
    assert static == pytest.approx(length ** 3 / (3 * E * section["I"]), rel=0.01)
    modes = solve_modal(fs, k=20)
    omega_beam = EULER_BERNOULLI_CANTILEVER[0] ** 2 * np.sqrt(E * section["I"] / (rho * section["A"] * length ** 4))
    assert 2 * np.pi * modes.frequency_Hz[0] == pytest.approx(omega_beam, rel=0.01)

    times = np.arange(601) * modes.period_s[0] / 400
    recorder = StepRecorder([point_channel("tip", tip, [0, 0, length])], len(times), keep=range(len(times)))
    result = solve_transient(fs, f[:, None], np.r_[0.0, np.ones(600)][:, None], times, observer=recorder)
    assert result.scheme == "reduced"
    w = np.array([tip[0] @ recorder.fields[n] for n in range(1, len(times))])
    omega = 2 * np.pi * modes.frequency_Hz
    weights = (tip[0] @ modes.shapes) * (modes.shapes.T @ f) / omega ** 2  # tip deflection per mode
    exact = static - weights.sum() + _ramped_step(omega, times[1:], result.dt_s) @ weights
    np.testing.assert_allclose(w, exact, rtol=0, atol=0.006 * static)
    assert w.max() == pytest.approx(2 * static, rel=0.02)


def test_a_start_in_quasi_static_equilibrium_has_no_initial_acceleration_unless_damped(model):
    """From u0 = K⁻¹f0 the out-of-balance force M a0 = f0 − K u0 − C v0 is round-off without
    damping (a0 = 0 exactly, no solve) and −C v0 with it."""
    from femstudy.fe.transient import _initial_acceleration

    fs, f, _ = model
    free = fs.bc.free
    u0 = solve_static(fs, f)[free]
    v0 = 10.0 * u0
    assert not np.any(_initial_acceleration(fs, f[free], u0, v0, (0.0, 0.0)))
    damped = _initial_acceleration(fs, f[free], u0, v0, (5.0, 0.0))  # C = 5 M: a0 = −5 v0
    # plus M⁻¹ of the solve's round-off force (measured 3e-4 of it here)
    assert np.linalg.norm(damped + 5.0 * v0) / np.linalg.norm(5.0 * v0) < 1e-3


@pytest.mark.skipif("pardiso" not in linsolve.available(), reason="MKL (PARDISO) not installed")
@pytest.mark.parametrize("steps_per_period", [None, 40])
def test_a_single_precision_factor_marches_to_the_double_precision_answer_one_substitution_per_block(
        model, steps_per_period):
    """On a single-precision factor nothing is refined (femstudy.fe.transient, 1'): one
    substitution call per block, and the fields and static shapes are the double-precision
    march's within 10 × the indicators, quasi-static and resolved."""
    fs, f, period = model
    times = np.linspace(0.0, 3.0, 31) if steps_per_period is None else np.arange(81) * period / steps_per_period
    load = np.sin(times / times[-1] * np.pi) ** 2
    single = factorize(fs.system, fs.bc, precision="single")
    (march, _, a), (reference, _, b) = (_march(s, f, load, times) for s in (single, fs))
    assert march.scheme == reference.scheme == "reduced"
    # quasi-static, both reach the target 1e-9; resolved, the double-precision march stops at 2e-9 on this tube
    assert march.indicator <= max(1e-9, 3 * reference.indicator), (march.indicator, reference.indicator)
    tolerance = 10 * max(reference.indicator, march.indicator, 1e-10)
    np.testing.assert_allclose(a, b, rtol=0, atol=tolerance * np.abs(b).max())
    np.testing.assert_allclose(march.static_shapes, reference.static_shapes, rtol=0,
                               atol=tolerance * np.abs(reference.static_shapes).max())
    assert single.factor.refinements == 0
    estimated = march.timings.get("indicator_estimated", False)
    assert march.timings["substitutions"] == len(march.timings["indicator_by_block"]) + 1 - estimated


@pytest.mark.skipif("pardiso" not in linsolve.available(), reason="MKL (PARDISO) not installed")
@pytest.mark.parametrize("steps_per_period", [None, 40])
def test_a_last_block_left_unsubstituted_keeps_its_estimate_above_the_true_indicator(model, steps_per_period):
    """In a quasi-static march, when the contraction seen promises the target, the last block is
    added without its substitution (femstudy.fe.transient, 1'): its estimated indicator must
    still bound the true ‖K⁻¹(M a + K u − f)‖ / max ‖u‖, here computed with the exact
    double-precision factor. A resolved march measures every block."""
    from femstudy.fe.transient import preconditioned_march

    fs, f, period = model
    times = np.linspace(0.0, 3.0, 31) if steps_per_period is None else np.arange(81) * period / steps_per_period
    load = (np.sin(times / times[-1] * np.pi) ** 2)[:, None]
    single = factorize(fs.system, fs.bc, precision="single")
    free = fs.bc.free
    P = f[free][:, None]
    zero = np.zeros(len(free))
    march = preconditioned_march(single, P, load, times[1] - times[0], (0.0, 0.0), (zero, zero))
    V = march.basis
    exact = np.linalg.norm(fs.factor.solve(fs.mass(V)) @ march.ay + V @ march.y - fs.factor.solve(P) @ load.T,
                           axis=0).max() / np.linalg.norm(V @ march.y, axis=0).max()
    estimated = march.timings.get("indicator_estimated", False)
    # 0.1 s steps are ~500 periods of the tube's lowest mode; a resolved march is not estimated
    assert estimated == (steps_per_period is None)
    if estimated:
        assert exact <= march.indicator <= 1e-9
        assert march.timings["substitutions"] == len(march.timings["indicator_by_block"])
    else:  # measured through the single-precision factor: within its contraction of the exact one
        assert exact == pytest.approx(march.indicator, rel=0.01)
