"""Linear solvers: every installed method gives the same answer, and the choice falls back
to pure scipy when the fast packages are missing."""

import logging

import numpy as np
import pytest

from fe_cases import clamped_both_ends, tube
from femstudy.errors import UserError
from femstudy.fe import factorize, linsolve


@pytest.fixture(scope="module")
def problem():
    # a stubby tube (L/D ≈ 2): well conditioned enough for AMG-CG to converge quickly too
    system = tube(2, 16, 6, 2, length=60.0)
    fs = factorize(system, clamped_both_ends(system, length=60.0), "superlu")
    b = np.random.default_rng(2).standard_normal((fs.n_free, 2))
    return fs.K, b, fs.near_null_space()


@pytest.mark.parametrize("method", linsolve.available())
def test_every_available_method_solves_the_system(problem, method):
    K, b, B = problem
    factor = linsolve.factorize(K, method, near_null=B)
    assert factor.method == method
    x = factor.solve(b)
    # direct solvers reach round-off (~1e-13 here); AMG-CG stops at a 1e-8 relative residual
    # measured in its preconditioner's norm, so allow ten times that in the plain norm
    assert np.linalg.norm(K @ x - b) < (1e-7 if method == "amg" else 1e-10) * np.linalg.norm(b)
    x0 = factor.solve(b[:, 0])
    np.testing.assert_allclose(x0, x[:, 0], rtol=1e-5, atol=1e-9 * np.abs(x).max())
    assert factor.solves == 2 and method in factor.describe()


def hide(monkeypatch, *packages):
    """Make ``linsolve`` believe the given packages are not installed."""
    real = linsolve._installed
    monkeypatch.setattr(linsolve, "_installed", lambda name: name not in packages and real(name))


def test_pure_scipy_fallback_runs_and_says_so(problem, monkeypatch, caplog):
    K, b, B = problem
    hide(monkeypatch, "mkl", "sksparse.cholmod")
    assert linsolve.available() == ["superlu", "amg"]
    with caplog.at_level(logging.INFO, logger="femstudy"):
        factor = linsolve.factorize(K, near_null=B)
    assert factor.method == "superlu"
    assert "linear solver superlu" in caplog.text
    assert np.linalg.norm(K @ factor.solve(b) - b) < 1e-10 * np.linalg.norm(b)
    # large problems go to AMG-CG, whose memory grows linearly, rather than to SuperLU
    assert linsolve.choose(10 * linsolve.SUPERLU_MAX_DOFS) == ["amg", "superlu"]
    hide(monkeypatch, "mkl", "sksparse.cholmod", "pyamg")
    assert linsolve.choose(10 * linsolve.SUPERLU_MAX_DOFS) == ["superlu"]


@pytest.mark.skipif("pardiso" not in linsolve.available(), reason="MKL (PARDISO) not installed")
def test_pardiso_that_does_not_fit_gives_way(problem, monkeypatch, caplog):
    K, b, B = problem
    monkeypatch.setattr(linsolve, "available_memory_bytes", lambda: 1024)
    with caplog.at_level(logging.INFO, logger="femstudy"):
        factor = linsolve.factorize(K, near_null=B)
    assert factor.method == "amg"  # no other direct method would fit either
    assert "pardiso does not fit in memory" in caplog.text
    with pytest.raises(UserError, match="does not fit in memory"):
        linsolve.factorize(K, "pardiso")


def test_solver_choice_can_be_forced_and_is_checked(problem, monkeypatch):
    K, b, B = problem
    assert linsolve.factorize(K, "superlu").method == "superlu"
    with pytest.raises(UserError, match="unknown linear solver 'mumps'"):
        linsolve.factorize(K, "mumps")
    hide(monkeypatch, "mkl")
    with pytest.raises(UserError, match="'pardiso' is not installed"):
        linsolve.factorize(K, "pardiso")
