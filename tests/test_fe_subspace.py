"""The subspace methods' dense tools: the thin SVD (through Gram matrices, or Householder QR
for nearly dependent columns) and the growing QR that the transient's error indicator reads."""

import numpy as np
import pytest

from femstudy.fe import subspace

N = 4000


def _blocks():
    rng = np.random.default_rng(7)
    base = rng.standard_normal((N, 4))
    return {
        "independent": rng.standard_normal((N, 6)),
        # columns 1 to 1e-12 in size (MQ beside KQ): the scaled Gram matrix is well conditioned
        "graded": rng.standard_normal((N, 6)) * np.logspace(0, -12, 6),
        # directions 1e-7 apart: too close for the Gram matrix, through Householder QR
        "nearly dependent": np.hstack([base, base]) + 1e-7 * rng.standard_normal((N, 8)),
        "with a zero column": np.column_stack([rng.standard_normal((N, 3)), np.zeros(N)]),
    }


@pytest.mark.parametrize("name, gram", [("independent", True), ("graded", True), ("nearly dependent", False),
                                        ("with a zero column", False)])
def test_thin_svd_is_lapacks_svd_to_round_off(name, gram):
    W = _blocks()[name]
    assert (subspace._gram_svd(W) is not None) == gram
    U, sigma, Vt = subspace.thin_svd(W)
    reference = np.linalg.svd(W, compute_uv=False)
    # orthonormal to round-off, each column of W rebuilt to round-off of its own size, and
    # the singular values LAPACK's (above round-off of the largest)
    np.testing.assert_allclose(U.T @ U, np.eye(U.shape[1]), rtol=0, atol=1e-14)
    rebuilt = (U * sigma) @ Vt
    sizes = np.maximum(np.linalg.norm(W, axis=0), 1e-300)
    assert np.max(np.linalg.norm(rebuilt - W, axis=0) / sizes * (sizes > 0)) < 1e-12
    meaningful = reference > 1e-13 * reference[0]
    np.testing.assert_allclose(sigma[meaningful], reference[meaningful], rtol=1e-10)


def test_growing_qr_keeps_the_norm_of_every_combination_of_its_columns():
    """‖G z‖ = ‖R z‖ for G grown by blocks of very different sizes and some columns inside the
    earlier span, as the transient's [MQ, KQ] blocks are; Q stays orthonormal."""
    rng = np.random.default_rng(11)
    blocks = [rng.standard_normal((N, 2)),
              rng.standard_normal((N, 4)) * np.array([1.0, 1.0, 1e-6, 1e-6])]
    inside = np.hstack(blocks) @ rng.standard_normal((6, 2))  # already in the span
    blocks.append(np.column_stack([inside, rng.standard_normal(N) * 1e-9]))
    qr = subspace.GrowingQR(N, 12)
    for block in blocks:
        qr.append(block)
    G = np.hstack(blocks)
    assert qr.rows == 7 and qr.cols == 9  # the two columns inside the span add no direction
    Q = qr.Q[:, :qr.rows]
    np.testing.assert_allclose(Q.T @ Q, np.eye(qr.rows), rtol=0, atol=1e-14)
    Z = rng.standard_normal((9, 20)) * np.logspace(0, 8, 9)[:, None]
    exact, through_R = np.linalg.norm(G @ Z, axis=0), np.linalg.norm(qr.R @ Z, axis=0)
    np.testing.assert_allclose(through_R, exact, rtol=1e-12)
    # a cancellation, as in a residual: the combination that is (nearly) zero stays nearly zero
    z = np.zeros(9)
    z[:6] = np.linalg.lstsq(np.hstack(blocks[:2]), inside[:, 0], rcond=None)[0]
    z[6] = -1.0
    assert np.linalg.norm(qr.R @ z) < 1e-12 * np.linalg.norm(inside[:, 0])


@pytest.mark.parametrize("nearly_inside", [False, True])
def test_growing_gram_keeps_the_norm_of_every_combination_and_combines_orthonormally(nearly_inside, monkeypatch):
    """‖X c‖ = ‖R c‖ and X R⁻¹ orthonormal, for blocks of graded sizes (K̃⁻¹ of [P, MQ, KQ]
    directions); a block 1e-7 from the earlier span is beyond the Gram matrix and goes through
    Householder QR, with the same guarantees."""
    householder = []
    qr = subspace.scipy.linalg.qr
    monkeypatch.setattr(subspace.scipy.linalg, "qr", lambda *a, **k: householder.append(1) or qr(*a, **k))
    rng = np.random.default_rng(5)
    blocks = [rng.standard_normal((N, 2)), rng.standard_normal((N, 4)) * np.logspace(0, -8, 4)]
    third = rng.standard_normal((N, 3))
    if nearly_inside:
        third[:, 0] = blocks[0][:, 0] + 1e-7 * rng.standard_normal(N)
    blocks.append(third)
    gram = subspace.GrowingGram(N, 12)
    for block in blocks:
        gram.append(block)
    X = np.hstack(blocks)
    assert gram.cols == 9 and gram.R.shape == (9, 9)
    assert bool(householder) == nearly_inside  # the last block only, when it is nearly inside
    C = rng.standard_normal((9, 20))
    np.testing.assert_allclose(np.linalg.norm(gram.R @ C, axis=0), np.linalg.norm(X @ C, axis=0), rtol=1e-9)
    Q = gram.combine(np.eye(9))
    np.testing.assert_allclose(Q.T @ Q, np.eye(9), rtol=0, atol=1e-6 if nearly_inside else 1e-9)
