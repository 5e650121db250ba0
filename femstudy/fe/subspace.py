"""Small dense tools for the subspace methods (reduced transient, block modal analysis)."""

from __future__ import annotations

import numpy as np
import scipy.linalg


def orthonormal_complement(V: np.ndarray, W: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
    """Orthonormal columns spanning what W adds to span(V) (V orthonormal); directions under
    ``rtol`` of W's own size are round-off and dropped."""
    scale = np.linalg.norm(W, axis=0).max()
    for _ in range(2):  # classical Gram–Schmidt twice is orthogonal to working precision
        W = W - V @ (V.T @ W)
    U, sigma, _ = thin_svd(W)
    return U[:, sigma > rtol * scale]


def thin_svd(W: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """W = U diag(σ) Vᵀ for a tall W (n × b, b small), through its Householder QR and the SVD
    of the b × b factor: as accurate, and faster than LAPACK's SVD of the tall matrix (0.34 M × 8
    on one thread: 20 + 2 ms against 33 ms for scipy's and 64–73 ms for numpy's)."""
    Q, R = scipy.linalg.qr(W, mode="economic", check_finite=False)
    U, sigma, Vt = np.linalg.svd(R)
    return Q @ U, sigma, Vt


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

    def append(self, W: np.ndarray) -> None:
        Q, rows, cols, b = self.Q[:, :self.rows], self.rows, self.cols, W.shape[1]
        sizes = np.linalg.norm(W, axis=0)
        sizes[sizes == 0] = 1.0
        W = W / sizes
        C = np.zeros((rows, b))
        for _ in range(2):
            step = Q.T @ W
            W = W - Q @ step
            C += step
        U, sigma, Vt = thin_svd(W)
        keep = sigma > 1e-12
        k = int(keep.sum())
        self.Q[:, rows:rows + k] = U[:, keep]
        self._R[:rows, cols:cols + b] = C * sizes
        self._R[rows:rows + k, cols:cols + b] = sigma[keep, None] * Vt[keep] * sizes
        self.rows, self.cols = rows + k, cols + b
