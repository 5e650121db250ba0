"""Bounded-variable least squares of the diagnosis fits (femstudy.diagnosis.bounded)."""

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from femstudy.diagnosis import bounded
from femstudy.diagnosis.bounded import bvls, bvls_from, least_squares


def _problem(rng, n):
    """An upper-triangular n × n system of full rank (as a fit passes: the R of a damped Jacobian)
    with columns of different scales, some variables bounded below by 0, some above by 1, the rest
    free."""
    A = np.triu(rng.normal(size=(n, n))) + np.diag(rng.uniform(0.5, 3.0, n) * rng.choice([-1.0, 1.0], n))
    A *= rng.lognormal(0.0, 1.0, n)[None, :]
    lower = np.where(rng.random(n) < 0.6, 0.0, -np.inf)
    upper = np.where(rng.random(n) < 0.3, 1.0, np.inf)
    return A, 3.0 * rng.normal(size=n), lower, upper


def test_bvls_agrees_with_scipy_lsq_linear_to_round_off_on_the_same_bounds():
    """The same variables on their bounds (to 1e-12: both leave round-off there) and the same
    solution to 1e-9 (relative to the largest coefficient) as scipy's BVLS on 500 random systems
    of 2 to 50 variables."""
    rng = np.random.default_rng(7)
    for _ in range(500):
        A, b, lower, upper = _problem(rng, int(rng.integers(2, 51)))
        ours, theirs = bvls(A, b, lower, upper), lsq_linear(A, b, bounds=(lower, upper), method="bvls").x
        for bound in (lower, upper):
            assert np.array_equal(np.abs(ours - bound) <= 1e-12, np.abs(theirs - bound) <= 1e-12)
        assert np.max(np.abs(ours - theirs)) <= 1e-9 * max(1.0, np.max(np.abs(theirs)))


def test_bvls_solution_satisfies_the_optimality_conditions():
    """Inside the bounds (to round-off), and the gradient Aᵀ(Ax − b) zero on free variables and
    pointing out of the box on bound ones (KKT)."""
    rng = np.random.default_rng(8)
    for _ in range(200):
        A, b, lower, upper = _problem(rng, int(rng.integers(2, 40)))
        x = bvls(A, b, lower, upper)
        assert np.all(x >= lower - 1e-12) and np.all(x <= upper + 1e-12)
        g = A.T @ (A @ x - b)
        scale = np.linalg.norm(A, axis=0) * np.linalg.norm(b)
        at_lower, at_upper = np.abs(x - lower) <= 1e-12, np.abs(x - upper) <= 1e-12
        free = ~(at_lower | at_upper)
        assert np.all(np.abs(g[free]) <= 1e-9 * scale[free])
        assert np.all(g[at_lower] >= -1e-9 * scale[at_lower]) and np.all(g[at_upper] <= 1e-9 * scale[at_upper])


def test_bvls_from_any_guess_of_the_bounds_finds_scipys_solution_and_from_the_right_one_in_fewer_steps(monkeypatch):
    """Started from the sides of the solution, from a random guess or from every variable on a
    bound, the same solution as scipy's BVLS (to 1e-9), and the sides it returns are where the
    solution sits; from the right sides it factorises fewer column sets than from none, summed
    over 300 random systems."""
    rng = np.random.default_rng(10)
    factorisations = {"none": 0, "right": 0}
    real = bounded._householder

    def counted(key):
        def householder(A, b):
            factorisations[key] += 1
            return real(A, b)
        return householder

    for _ in range(300):
        A, b, lower, upper = _problem(rng, int(rng.integers(2, 41)))
        theirs = lsq_linear(A, b, bounds=(lower, upper), method="bvls").x
        monkeypatch.setattr(bounded, "_householder", counted("none"))
        x, sides = bvls_from(A, b, lower, upper, None)
        assert np.array_equal(sides != 0, (np.abs(x - lower) <= 1e-12) | (np.abs(x - upper) <= 1e-12))
        monkeypatch.setattr(bounded, "_householder", counted("right"))
        from_right = bvls_from(A, b, lower, upper, sides)[0]
        monkeypatch.setattr(bounded, "_householder", real)
        guesses = [rng.choice([-1.0, 0.0, 1.0], A.shape[1]), np.where(np.isfinite(lower), -1.0, 1.0)]
        for found in [from_right] + [bvls_from(A, b, lower, upper, g)[0] for g in guesses]:
            assert np.max(np.abs(found - theirs)) <= 1e-9 * max(1.0, np.max(np.abs(theirs)))
    assert factorisations["right"] < 0.5 * factorisations["none"]


def test_bvls_returns_the_unbounded_solution_when_it_is_inside():
    A = np.array([[2.0, 1.0], [0.0, 1.0]])
    x = bvls(A, np.array([3.0, 0.5]), np.zeros(2), np.full(2, 5.0))
    assert x == pytest.approx([1.25, 0.5], abs=1e-14)


def test_least_squares_matches_the_svd_solution_and_falls_back_on_a_deficient_rank():
    rng = np.random.default_rng(9)
    A, b = rng.normal(size=(30, 12)), rng.normal(size=30)
    assert least_squares(A, b) == pytest.approx(np.linalg.lstsq(A, b, rcond=None)[0], abs=1e-12)
    deficient = np.column_stack([A[:, :3], A[:, 0] + A[:, 1]])   # rank 3 of 4: minimum-norm solution
    assert least_squares(deficient, b) == pytest.approx(np.linalg.lstsq(deficient, b, rcond=None)[0], abs=1e-10)
    assert least_squares(np.zeros((5, 0)), b[:5]).size == 0
