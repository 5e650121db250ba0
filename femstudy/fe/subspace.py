"""Small dense tools for the subspace methods (reduced transient, block modal analysis)."""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.linalg.blas


def orthonormal_complement(V: np.ndarray, W: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
    """Orthonormal columns spanning what W adds to span(V) (V orthonormal); directions under
    ``rtol`` of W's own size are round-off and dropped."""
    scale = column_norms(W).max()
    W, _ = project_out(V, W)
    U, sigma, _ = thin_svd(W)
    return U[:, sigma > rtol * scale]


def column_norms(W: np.ndarray) -> np.ndarray:
    """The 2-norm of every column of W (one pass, no temporary of W's size)."""
    return np.sqrt(np.einsum("ij,ij->j", W, W))


def project_out(Q: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(W − Q C, C) with C = QᵀW for an orthonormal Q, by classical Gram–Schmidt twice (orthogonal
    to working precision), on a column-major copy of W (:func:`project_out_in_place`)."""
    return project_out_in_place(Q, np.array(W, dtype=float, order="F"))


def project_out_in_place(Q: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_out` overwriting W, which must be column-major float64 (BLAS dgemm
    updates it in place)."""
    C = np.zeros((Q.shape[1], W.shape[1]))
    for _ in range(2 if Q.shape[1] else 0):
        step = Q.T @ W
        W = scipy.linalg.blas.dgemm(-1.0, Q, step, 1.0, W, overwrite_c=True)
        C += step
    return W, C


#: Condition number of a block's column-scaled Gram matrix up to which :func:`thin_svd` goes
#: through it (κ² ≤ 1e10: its eigenvalues then hold ~6 digits, and the second pass restores
#: orthogonality to round-off); beyond, through Householder QR.
GRAM_CONDITION = 1e10


def thin_svd(W: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """W = U diag(σ) Vᵀ for a tall W (n × b, b small).

    Through the Gram matrix of W's columns scaled to unit size (D the column norms):
    (WD⁻¹)ᵀ(WD⁻¹) = V₁Λ₁V₁ᵀ gives U₁ = WD⁻¹V₁Λ₁^-½, whose own Gram matrix V₂Λ₂V₂ᵀ gives the
    orthonormal U₂ = U₁V₂Λ₂^-½ and W = U₂T with T = Λ₂^½V₂ᵀΛ₁^½V₁ᵀD; the SVD of the b × b T
    finishes it. Four passes over W (two Gram products, two products with b × b matrices)
    instead of Householder's QR and its Q: 110 k × 8 on one thread, 4 ms against 12 ms. The
    scaling makes columns of very different sizes (MQ and KQ) as easy as equal ones; only
    nearly dependent directions (scaled condition above √:data:`GRAM_CONDITION`, or a zero
    column) go through Householder QR and the SVD of its R."""
    through_gram = _gram_svd(W)
    if through_gram is not None:
        return through_gram
    Q, R = scipy.linalg.qr(W, mode="economic", check_finite=False)
    U, sigma, Vt = np.linalg.svd(R)
    return Q @ U, sigma, Vt


def _gram_svd(W: np.ndarray):
    """:func:`thin_svd` through Gram matrices; None when W is too ill-conditioned for them."""
    gram = W.T @ W
    d = np.sqrt(np.diag(gram))
    if not np.all(d > 0):
        return None
    lam1, V1 = np.linalg.eigh(gram / np.outer(d, d))
    if lam1[0] * GRAM_CONDITION < lam1[-1]:
        return None
    U1 = W @ (V1 / d[:, None] / np.sqrt(lam1))
    lam2, V2 = np.linalg.eigh(U1.T @ U1)
    T = (np.sqrt(lam2)[:, None] * V2.T) @ (np.sqrt(lam1)[:, None] * V1.T * d)
    Ut, sigma, Vt = np.linalg.svd(T)
    return U1 @ (V2 / np.sqrt(lam2) @ Ut), sigma, Vt


def symmetric(A: np.ndarray) -> np.ndarray:
    return (A + A.T) / 2


def grow_projection(Ar: np.ndarray, V: np.ndarray, AQ: np.ndarray, k: int) -> np.ndarray:
    """[[Ar, VᵀAQ'], [·, QᵀAQ]]: Ar = V'ᵀAV' extended by the last k columns Q of V (A symmetric)."""
    border = V.T @ AQ  # (m, k): old rows then the new block's
    out = np.empty((len(V.T), len(V.T)))
    out[:-k, :-k] = Ar
    out[:, -k:] = border
    out[-k:, :-k] = border[:-k].T
    return out


class GrowingQR:
    """A factor R with ‖G z‖ = ‖R z‖ for every z, for a G whose columns arrive in blocks:
    G = Q R with Q orthonormal. Each block is orthogonalised against Q (classical Gram–Schmidt,
    twice), its columns first brought to unit size; what is left is added to Q only in its
    directions above 1e-12 (a Krylov block nearly inside the earlier ones would otherwise add
    round-off directions and spoil Q's orthogonality). Judged column by column, because a
    block may hold columns of very different sizes, as [MQ, KQ] does (MQ is ~1/ω² of KQ): with
    one scale for the block, the test tube's resolved march on a single-precision factor lost
    MQ's directions and stalled at an indicator of 2e-8; judged by column it reaches 6e-10."""

    def __init__(self, n: int, capacity: int):
        self.Q = np.empty((n, capacity), order="F")  # column-major: memory only for the columns written
        self._R = np.zeros((capacity, capacity))
        self.rows = self.cols = 0

    @property
    def R(self) -> np.ndarray:
        return self._R[:self.rows, :self.cols]

    def append(self, *blocks: np.ndarray) -> None:
        """Add the columns of ``blocks`` (each n × b_i), in order: e.g. MQ and KQ, not stacked first."""
        Q, rows, cols = self.Q[:, :self.rows], self.rows, self.cols
        sizes = np.concatenate([column_norms(B) for B in blocks])
        sizes[sizes == 0] = 1.0
        b = len(sizes)
        # brought to unit size where Q's next columns will be, and orthogonalised there
        W, start = self.Q[:, rows:rows + b], 0
        for B in blocks:
            np.divide(B, sizes[start:start + B.shape[1]], out=W[:, start:start + B.shape[1]])
            start += B.shape[1]
        W, C = project_out_in_place(Q, W)
        U, sigma, Vt = thin_svd(W)
        keep = sigma > 1e-12
        k = int(keep.sum())
        self.Q[:, rows:rows + k] = U if k == b else U[:, keep]
        self._R[:rows, cols:cols + b] = C * sizes
        self._R[rows:rows + k, cols:cols + b] = sigma[keep, None] * Vt[keep] * sizes
        self.rows, self.cols = rows + k, cols + b


class GrowingGram:
    """A factor R with ‖X c‖ = ‖R c‖ for every c, for an X whose columns arrive in blocks,
    through X's Gram matrix (X = Q R, Q = X R⁻¹ orthonormal, never formed): each block costs
    one product of X with it, where a QR reads Q four times and the block about ten.

    For products X c whose terms do not cancel, as K̃⁻¹ of residuals given in orthonormal
    coordinates: the Gram matrix's round-off (~1e-13 of its scaled entries) then moves ‖X c‖
    by far less than the 1e-9 it is read to (measured: 1e-11 relative on the femur and the
    tube). R is the Cholesky factor of the column-scaled Gram matrix, scaled back; when a
    column lies nearly inside the earlier ones (a pivot² below 1/:data:`GRAM_CONDITION`) the
    Gram matrix no longer holds it, and R comes from Householder QR of X instead."""

    def __init__(self, n: int, capacity: int):
        self.X = np.empty((n, capacity), order="F")  # column-major: memory only for the columns written
        self._gram = np.zeros((capacity, capacity))
        self.cols = 0
        self.R = np.zeros((0, 0))

    def append(self, W: np.ndarray) -> None:
        start, b = self.cols, W.shape[1]
        self.X[:, start:start + b] = W
        self.cols = end = start + b
        border = self.X[:, :end].T @ self.X[:, start:end]
        self._gram[:end, start:end] = border
        self._gram[start:end, :start] = border[:start].T
        gram = self._gram[:end, :end]
        d = np.sqrt(np.diag(gram))
        try:
            R = np.linalg.cholesky(gram / np.outer(d, d)).T if np.all(d > 0) else None
        except np.linalg.LinAlgError:
            R = None
        if R is not None and np.diag(R).min() ** 2 * GRAM_CONDITION >= 1:
            self.R = R * d
        else:
            self.R = scipy.linalg.qr(self.X[:, :end], mode="r", check_finite=False)[0][:end]

    def combine(self, U: np.ndarray) -> np.ndarray:
        """Q U = X R⁻¹ U: columns of the orthonormal Q given in its coordinates."""
        return self.X[:, :self.cols] @ scipy.linalg.solve_triangular(self.R, U, check_finite=False)
