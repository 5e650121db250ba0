"""Intel MKL PARDISO through its documented C interface (``pardiso`` in MKL's runtime library).

Only what femstudy's solver needs: a real symmetric positive definite matrix (mtype 2) given
as its upper triangle in CSR, analysed (phase 11), factorised (22) and solved (33) as separate
calls, in double or single precision (iparm 28), and released (−1). The ``mkl`` wheel ships the
runtime library; it is found through that package's file list, else the system's library path.

Why not a wrapper package: pypardiso's public interface factorises in one call (no memory
check between the analysis and the factorisation), accepts double precision only, and hashes
the matrix again at every solve; this module is the 1:1 call of the library's own interface.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from functools import lru_cache
from pathlib import Path

import numpy as np
import scipy.sparse as sp

#: PARDISO's error codes (MKL's documentation, "pardiso": error).
ERRORS = {-1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
          -4: "zero pivot (the matrix is not positive definite)", -5: "internal error",
          -7: "diagonal matrix is singular", -8: "32-bit integer overflow", -9: "not enough memory for OOC",
          -10: "cannot open OOC files", -11: "OOC read/write error", -12: "wrong 64-bit library"}


class PardisoError(RuntimeError):
    """PARDISO returned a non-zero error code."""

    def __init__(self, phase: int, code: int):
        super().__init__(f"PARDISO phase {phase} failed: error {code} ({ERRORS.get(code, 'unknown')})")
        self.code = code


@lru_cache(maxsize=1)
def runtime_path() -> str | None:
    """Where MKL's single dynamic library (libmkl_rt) is: the ``mkl`` package's copy, else the
    system's (``ctypes.util.find_library``); None when there is none."""
    from importlib.metadata import PackageNotFoundError, files
    try:
        found = sorted((f for f in files("mkl") or () if f.name.startswith("libmkl_rt.so")), key=lambda f: len(f.name))
        for f in found:
            path = Path(f.locate())
            if path.exists():
                return str(path.resolve())
    except PackageNotFoundError:
        pass
    return ctypes.util.find_library("mkl_rt")


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    path = runtime_path()
    if path is None:
        raise ImportError("MKL's runtime library (libmkl_rt) is not installed")
    lib = ctypes.CDLL(path)
    i32 = ctypes.POINTER(ctypes.c_int32)
    # void pardiso(_MKL_DSS_HANDLE_t pt, maxfct, mnum, mtype, phase, n, a, ia, ja, perm, nrhs,
    #              iparm, msglvl, b, x, error): every integer by pointer, 32-bit (LP64 interface)
    lib.pardiso.argtypes = [ctypes.c_void_p, i32, i32, i32, i32, i32, ctypes.c_void_p, i32, i32, i32, i32, i32, i32,
                            ctypes.c_void_p, ctypes.c_void_p, i32]
    lib.pardiso.restype = None
    return lib


def max_threads() -> int:
    """The threads MKL may use now (a worker process's threadpoolctl limit, else its default:
    the cores), 1 where MKL is not installed."""
    try:
        return max(1, int(_library().mkl_get_max_threads()))
    except (ImportError, AttributeError):
        return 1


def load() -> None:
    """Load MKL's runtime now (so that a thread limit set next, e.g. by threadpoolctl, reaches it)."""
    _library()


class SymmetricPositiveDefinite:
    """One PARDISO handle for an SPD matrix given by its upper triangle ``upper``, sorted
    indices, float64 or float32 (the precision of the factorisation and the solves): CSR, or
    BSR of square blocks (the upper triangle of blocks, diagonal blocks whole), which PARDISO
    orders and analyses on the block graph (iparm 37).

    ``iparm`` entries are set by their 1-based numbers, as MKL's documentation numbers them.
    """

    def __init__(self, upper: sp.csr_matrix | sp.bsr_matrix, iparm: dict[int, int]):
        block = upper.blocksize[0] if upper.format == "bsr" else 1
        self.n = upper.shape[0] // block  # PARDISO's n counts block rows
        self.dtype = np.dtype(upper.dtype)
        if self.dtype not in (np.float32, np.float64):
            raise TypeError(f"PARDISO takes float32 or float64, not {self.dtype}")
        self.a = np.ascontiguousarray(upper.data).reshape(-1)  # BSR blocks row by row, as PARDISO reads them
        self.ia = np.ascontiguousarray(upper.indptr, dtype=np.int32)
        self.ja = np.ascontiguousarray(upper.indices, dtype=np.int32)
        self.pt = np.zeros(64, np.int64)  # PARDISO's internal handle: zero before the first call
        self.iparm = np.zeros(64, np.int32)
        self.iparm[0] = 1  # these settings, not the defaults
        self.iparm[27] = self.dtype == np.float32  # iparm 28: single precision
        self.iparm[34] = 1  # iparm 35: zero-based indices, as scipy's (no one-based copies)
        self.iparm[36] = block if block > 1 else 0  # iparm 37: BSR block size
        for number, value in iparm.items():
            self.iparm[number - 1] = value
        self._lib = _library()
        self._open = False

    def _call(self, phase: int, b: np.ndarray | None = None) -> np.ndarray | None:
        nrhs = 1 if b is None or b.ndim == 1 else b.shape[1]
        x = None if b is None else np.empty_like(b)
        error = ctypes.c_int32(0)
        i32 = ctypes.POINTER(ctypes.c_int32)

        def ref(value):
            return ctypes.byref(ctypes.c_int32(value))

        self._lib.pardiso(self.pt.ctypes.data, ref(1), ref(1), ref(2), ref(phase), ref(self.n), self.a.ctypes.data,
                          self.ia.ctypes.data_as(i32), self.ja.ctypes.data_as(i32), None, ref(nrhs),
                          self.iparm.ctypes.data_as(i32), ref(0), None if b is None else b.ctypes.data,
                          None if x is None else x.ctypes.data, ctypes.byref(error))
        if error.value:
            raise PardisoError(phase, error.value)
        return x

    def analyse(self) -> int:
        """Ordering and symbolic factorisation; returns the memory [bytes] PARDISO plans for
        the numeric factorisation (the larger of its analysis peak, iparm 15, and its
        permanent plus factorisation memory, iparm 16 + 17)."""
        self._open = True
        self._call(11)
        return 1024 * int(max(self.iparm[14], self.iparm[15] + self.iparm[16]))

    def factorize(self) -> None:
        self._call(22)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with A x = b for b (n,) or (n, k), in the factor's precision."""
        b = np.asarray(b, dtype=self.dtype, order="F")
        return self._call(33, b)

    def release(self) -> None:
        """Free all of PARDISO's memory for this handle."""
        if self._open:
            self._open = False
            self._call(-1)
