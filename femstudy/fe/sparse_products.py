"""A sparse matrix (CSR, or BSR of 3×3 node blocks) times a dense block of columns.

With MKL installed the product is MKL's sparse BLAS (``mkl_sparse_d_mm``, through the
``sparse_dot_mkl`` package): the matrix is read once for all columns, in MKL's threads. scipy's
product reads it once per column in one thread. On the 16 mm femur's K (8.6 M entries, BSR):
one column 3.8 ms against scipy's 12.3 ms, eight columns 7.3 ms against 57.8 ms (2 cores).
Without MKL, the columns go through scipy one by one (its product with a block of columns was
slower: two columns of the 3.5 mm femur's K, 0.17 s against 0.12 s one after the other).
"""

from __future__ import annotations

import functools
import os

import numpy as np
import scipy.sparse as sp


def times(A: sp.csr_matrix | sp.bsr_matrix, X: np.ndarray) -> np.ndarray:
    """A @ X for X (n,) or (n, k), float64; the same shape as A @ X."""
    X = np.asarray(X, dtype=float)
    mkl = _mkl_product()
    if mkl is not None and A.dtype == np.float64:
        return mkl(A, np.ascontiguousarray(X))
    if X.ndim == 1:
        return A @ X
    return np.column_stack([A @ X[:, j] for j in range(X.shape[1])]) if X.shape[1] else A @ X


@functools.cache
def _mkl_product():
    """sparse_dot_mkl's product, loaded from the runtime PARDISO uses; None without MKL."""
    from femstudy.fe import pardiso

    path = pardiso.runtime_path()
    if path is None:
        return None
    os.environ.setdefault("MKL_RT", path)  # the package's documented way to name the library
    try:
        from sparse_dot_mkl import dot_product_mkl
    except ImportError:
        return None
    return dot_product_mkl
