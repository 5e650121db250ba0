"""Small dense tools for the subspace methods (reduced transient, block modal analysis)."""

from __future__ import annotations

import numpy as np


def orthonormal_complement(V: np.ndarray, W: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
    """Orthonormal columns spanning what W adds to span(V) (V orthonormal); directions under
    ``rtol`` of W's own size are round-off and dropped."""
    scale = np.linalg.norm(W, axis=0).max()
    for _ in range(2):  # classical Gram–Schmidt twice is orthogonal to working precision
        W = W - V @ (V.T @ W)
    U, sigma, _ = np.linalg.svd(W, full_matrices=False)
    return U[:, sigma > rtol * scale]


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
    twice); what is left is added to Q only in its directions above 1e-12 of the block's
    size (a Krylov block nearly inside the earlier ones would otherwise add round-off
    directions and spoil Q's orthogonality)."""

    def __init__(self, n: int, capacity: int):
        self.Q = np.empty((n, capacity), order="F")  # column-major: memory only for the columns written
        self._R = np.zeros((capacity, capacity))
        self.rows = self.cols = 0

    @property
    def R(self) -> np.ndarray:
        return self._R[:self.rows, :self.cols]

    @property
    def size(self) -> tuple[int, int]:
        """(rows, columns) of R: where :meth:`truncate` can return to."""
        return self.rows, self.cols

    def truncate(self, size: tuple[int, int]) -> None:
        """Forget the blocks appended since R had ``size`` (:attr:`size`)."""
        self.rows, self.cols = size
        self._R[self.rows:, self.cols:] = 0.0

    def append(self, W: np.ndarray) -> None:
        Q, rows, cols, b = self.Q[:, :self.rows], self.rows, self.cols, W.shape[1]
        scale = np.linalg.norm(W, axis=0).max()
        C = np.zeros((rows, b))
        for _ in range(2):
            step = Q.T @ W
            W = W - Q @ step
            C += step
        U, sigma, Vt = np.linalg.svd(W, full_matrices=False)
        keep = sigma > 1e-12 * scale
        k = int(keep.sum())
        self.Q[:, rows:rows + k] = U[:, keep]
        self._R[:rows, cols:cols + b] = C
        self._R[rows:rows + k, cols:cols + b] = sigma[keep, None] * Vt[keep]
        self.rows, self.cols = rows + k, cols + b
