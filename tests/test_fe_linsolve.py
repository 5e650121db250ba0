"""Linear solvers: every installed method gives the same answer, and the choice falls back
to pure scipy when the fast packages are missing."""

import logging

import numpy as np
import pytest
import scipy.sparse as sp

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


@pytest.mark.skipif("pardiso" not in linsolve.available(), reason="MKL (PARDISO) not installed")
def test_single_precision_factor_refines_to_the_double_precision_answer(problem):
    K, b, B = problem
    single, double = linsolve.factorize(K, "pardiso", precision="single"), linsolve.factorize(K, "pardiso")
    assert (single.precision, double.precision) == ("single", "double")
    x, y = single.solve(b), double.solve(b)
    assert single.refinements >= 2 and double.refinements == 0  # one single-precision solve is far off
    np.testing.assert_allclose(x, y, rtol=0, atol=1e-11 * np.abs(y).max())
    assert np.linalg.norm(K @ x - b) < 1e-12 * np.linalg.norm(b)


@pytest.mark.skipif("pardiso" not in linsolve.available(), reason="MKL (PARDISO) not installed")
def test_a_stalled_refinement_factorises_again_in_double_precision(problem, monkeypatch, caplog):
    K, b, B = problem
    factor = linsolve.factorize(K, "pardiso", precision="single")
    # never converged, not even by a correction of exactly zero, so it stalls at round-off
    # (or runs out of steps)
    monkeypatch.setattr(linsolve, "REFINE_RTOL", -1.0)
    monkeypatch.setattr(linsolve, "REFINE_FLOOR", -1.0)
    with caplog.at_level(logging.WARNING, logger="femstudy"):
        x = factor.solve(b)
    assert "factorising in double precision" in caplog.text and factor.precision == "double"
    assert np.linalg.norm(K @ x - b) < 1e-12 * np.linalg.norm(b)


@pytest.mark.skipif("pardiso" not in linsolve.available(), reason="MKL (PARDISO) not installed")
def test_pardiso_takes_node_blocks_or_entries_and_refuses_an_indefinite_matrix(problem):
    from femstudy.fe import pardiso
    K, b, B = problem
    blocks = linsolve.pardiso_upper(K, np.float64)
    assert blocks.format == "bsr" and blocks.blocksize == (3, 3)
    entries = linsolve.upper_triangle(K)
    assert abs(sp.triu(K) - entries).max() == 0 and abs(sp.triu(K) - sp.triu(blocks.tocsr())).max() == 0
    answers = []
    for upper in (blocks, entries):
        handle = pardiso.SymmetricPositiveDefinite(upper, {})
        handle.analyse()
        handle.factorize()
        answers.append(handle.solve(b))
        handle.release()
    np.testing.assert_allclose(answers[0], answers[1], rtol=0, atol=1e-9 * np.abs(answers[1]).max())
    # scattered unknowns (no 3×3 structure) go as entries; −K has no Cholesky factor
    order = np.random.default_rng(0).permutation(K.shape[0])
    assert linsolve.pardiso_upper(sp.csr_matrix(K[order][:, order]), np.float64).format == "csr"
    handle = pardiso.SymmetricPositiveDefinite(linsolve.upper_triangle(-K), {})
    handle.analyse()
    with pytest.raises(pardiso.PardisoError, match="not positive definite"):
        handle.factorize()
    handle.release()


@pytest.mark.parametrize("mkl", [True, False])
@pytest.mark.parametrize("threads", [1, 2])
def test_restricted_product_equals_the_restricted_block_times_the_columns(threads, mkl, monkeypatch):
    """MKL's product of all columns at once, or (without MKL) scipy's column by column: the
    same numbers as the restricted block times the whole block of columns, for node blocks (K,
    BSR) and entries (the nodal mass, CSR), whatever the thread limit."""
    from threadpoolctl import threadpool_limits

    from femstudy.fe import sparse_products

    if mkl and sparse_products._mkl_product() is None:
        pytest.skip("MKL's sparse BLAS (sparse_dot_mkl) not installed")
    if not mkl:
        monkeypatch.setattr(sparse_products, "_mkl_product", lambda: None)
    rng = np.random.default_rng(3)
    A = sp.random(60, 60, density=0.2, random_state=4, format="csr")
    A = A + A.T
    positions = np.sort(rng.choice(60, 45, replace=False))
    X = rng.standard_normal((45, 3))
    expected = A.toarray()[np.ix_(positions, positions)] @ X
    for matrix in (A.tobsr(blocksize=(3, 3)), A.tocsr()):
        with threadpool_limits(threads):
            got = linsolve.restricted_product(matrix, positions, X)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-13 * np.abs(expected).max())
        np.testing.assert_allclose(linsolve.restricted_product(matrix, positions, X[:, 1]), expected[:, 1],
                                   rtol=0, atol=1e-13 * np.abs(expected).max())


@pytest.mark.skipif("pardiso" not in linsolve.available(), reason="MKL (PARDISO) not installed")
@pytest.mark.parametrize("columns", [2, 3])
def test_two_or_three_columns_substituted_as_one_or_four_give_each_column_its_own_answer(problem, columns):
    """Two columns go one at a time and three as four (PARDISO runs 2–3 columns in one
    thread): each column's answer is the one-column substitution's, to single precision."""
    from threadpoolctl import threadpool_limits

    K, _, _ = problem
    B = np.random.default_rng(5).standard_normal((K.shape[0], columns))
    factor = linsolve.factorize(K, "pardiso", precision="single")
    for threads in (1, 2):
        with threadpool_limits(threads):
            X = factor.approximate(B)
        assert X.shape == B.shape and X.dtype == np.float64
        for j in range(columns):
            alone = factor.approximate(B[:, j])
            np.testing.assert_allclose(X[:, j], alone, rtol=0, atol=1e-5 * np.abs(alone).max())
