"""Newmark average acceleration: step loads, energy, damping and the quasi-static limit."""

import numpy as np
import pytest

from fe_cases import clamped_both_ends, mid_slice_load, tube
from femstudy.errors import UserError
from femstudy.fe import solve_modal, solve_static, solve_transient, step_check


@pytest.fixture(scope="module")
def model():
    system = tube(1, 12, 12, 2)  # 5.4k DOFs: the time integrator, not the mesh, is under test
    bc = clamped_both_ends(system)
    f = mid_slice_load(system, width=100.0)
    period = solve_modal(system, bc, k=1).period_s[0]
    return system, bc, f, period


def test_suddenly_applied_load_peaks_at_twice_static_and_oscillates_about_it(model):
    system, bc, f, period = model
    static = f @ solve_static(system, bc, f)
    times = np.arange(65) * period / 40  # 1.6 periods of the first mode, 40 steps each
    history = solve_transient(system, bc, f[:, None], np.ones((len(times), 1)), times,
                              observe=lambda n, t, u: {"deflection_mm": f @ u}, quasi_static=True)
    w = history.summary["deflection_mm"] / static
    assert w[0] == 0.0
    # undamped step response Σ c_i (1 − cos ω_i t), c_i ≥ 0: never above 2 × static; the first
    # mode carries almost all of it, so the sampled peak reaches 2 × static within 5 %
    assert 1.95 < w.max() <= 2.0 + 1e-9
    assert (w.max() + w.min()) / 2 == pytest.approx(1.0, abs=0.03)
    assert 1.95 < history.quasi_static["dynamic_amplification"] <= 2.0 + 1e-9


def test_free_vibration_conserves_energy(model):
    system, bc, f, period = model
    u0 = solve_static(system, bc, f)
    times = np.arange(61) * period / 20
    history = solve_transient(system, bc, f[:, None], np.zeros((len(times), 1)), times, u0=u0, energies=True)
    energy = history.summary["kinetic_energy_mJ"] + history.summary["strain_energy_mJ"]
    assert energy[0] == pytest.approx(0.5 * u0 @ system.K @ u0, rel=1e-12)
    # 1e-6 relative (the tolerance): the rule conserves it exactly; what drifts is
    # each step's linear-solve round-off
    assert np.abs(energy / energy[0] - 1).max() < 1e-6
    assert history.summary["kinetic_energy_mJ"].max() > 0.5 * energy[0]  # it really vibrates


def test_rayleigh_damping_only_dissipates(model):
    system, bc, f, period = model
    u0 = solve_static(system, bc, f)
    times = np.arange(61) * period / 20
    zeta, omega = 0.05, 2 * np.pi / period
    history = solve_transient(system, bc, f[:, None], np.zeros((len(times), 1)), times, u0=u0, energies=True,
                              damping=(2 * zeta * omega, 0.0), )
    energy = history.summary["kinetic_energy_mJ"] + history.summary["strain_energy_mJ"]
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])
    # C = αM with α = 2ζω damps the first mode by ζ: its energy decays as exp(−2ζωt); the
    # higher modes, damped less, hold a few per cent of it
    assert energy[-1] / energy[0] == pytest.approx(np.exp(-2 * zeta * omega * times[-1]), rel=0.5)


def test_thesis_time_steps_give_the_quasi_static_answer(model):
    system, bc, f, period = model
    times = np.linspace(0.0, 3.0, 31)  # the thesis's 0.1 s steps, thousand times the period
    ramp = np.exp(times)[:, None] - 1  # a smooth, growing load from zero
    history = solve_transient(system, bc, f[:, None], ramp, times, keep=[10, -1], quasi_static=True)
    check = step_check(period, history.dt_s)
    assert check["verdict"] == "quasi-static" and check["steps_per_period"] < 0.1
    # Δt ≫ T: each step returns the static solution of its load (to ~ (T/Δt)², far below 1e-3)
    assert history.quasi_static["dynamic_amplification"] == pytest.approx(1.0, abs=1e-3)
    np.testing.assert_allclose(history.summary["max_deflection_mm"],
                               history.summary["quasi_static_max_deflection_mm"], rtol=1e-3, atol=1e-12)
    assert sorted(history.fields) == [10, 30]
    static = solve_static(system, bc, f) * ramp[30, 0]
    np.testing.assert_allclose(history.fields[30], static, rtol=0, atol=1e-3 * np.abs(static).max())


def test_step_check_and_time_grid_errors():
    assert step_check(0.01, 0.0005)["verdict"] == "resolved"
    assert step_check(0.01, 0.0005)["period_elongation"] == pytest.approx(np.pi ** 2 / 12 * 0.05 ** 2)
    assert step_check(0.01, 0.003)["verdict"] == "under-resolved"
    system = tube(1, 12, 12, 2)
    bc = clamped_both_ends(system)
    with pytest.raises(UserError, match="uniform"):
        solve_transient(system, bc, np.zeros((system.n_dofs, 1)), np.zeros((3, 1)), [0.0, 0.1, 0.3])


@pytest.mark.parametrize("damping, start", [((0.0, 0.0), "rest"), ((30.0, 1e-4), "displaced")])
def test_krylov_march_reproduces_stepping_when_steps_are_long(model, damping, start):
    """At the thesis's 0.1 s steps a few Krylov vectors carry the whole march: same fields as
    stepping to 1e-9, Rayleigh damping and a displaced start included."""
    system, bc, f, period = model
    times = np.linspace(0.0, 3.0, 31)
    load = (np.sin(times) ** 2)[:, None]
    u0 = None if start == "rest" else 0.5 * solve_static(system, bc, f)
    runs = {scheme: solve_transient(system, bc, f[:, None], load, times, damping=damping, u0=u0, keep=range(31),
                                    scheme=scheme) for scheme in ("auto", "stepping")}
    assert runs["auto"].scheme == "krylov" and runs["stepping"].scheme == "stepping"
    assert runs["auto"].timings["krylov_vectors"] < 16 and runs["auto"].timings["krylov_residual"] <= 1e-9
    scale = max(np.abs(u).max() for u in runs["stepping"].fields.values())
    for n in range(31):
        np.testing.assert_allclose(runs["auto"].fields[n], runs["stepping"].fields[n], rtol=0, atol=1e-9 * scale)


def test_resolved_vibration_falls_back_to_stepping(model):
    """With 20 steps per period the Krylov vectors do not converge: the march steps."""
    system, bc, f, period = model
    times = np.arange(61) * period / 20
    history = solve_transient(system, bc, f[:, None], np.ones((61, 1)), times)
    assert history.scheme == "stepping"
