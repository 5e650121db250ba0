"""Solutions of K x = b kept between runs: a study repeated on the same model factorises nothing.

A :class:`KeptSolutions` solver holds an orthonormal set of right-hand sides U (n, r) and
their solutions Z = K⁻¹U, with each pair's residual eᵢ = ‖K zᵢ − uᵢ‖. A right-hand side b is
served as x = Z Uᵀb when its part outside span(U) and the kept residuals bound the residual
of x below :data:`RTOL` of ‖b‖:

    ‖K x − b‖ ≤ ‖b − U Uᵀb‖ + Σᵢ |uᵢᵀb| eᵢ ≤ RTOL ‖b‖.

Otherwise the matrix is factorised (once, on the first such b), the new directions of b are
orthonormalised against U (:func:`~femstudy.fe.subspace.orthonormal_complement`), solved,
checked and added, and x comes from the grown set. Solving for orthonormal directions rather than for b itself keeps
the bound free of any amplification by nearly dependent right-hand sides.

The set is stored under the SHA-256 of K's pattern and values (:func:`fingerprint`), so only
an identical matrix finds it; on loading, a random combination of the kept pairs is checked
against K (one product) before any of them is used. Every solve of a repeated study — its
static shapes, Krylov blocks and the hole models' — is a combination of the first run's
right-hand sides to round-off, and is served without a factorisation (its modal analysis
solves nothing: the modes are kept too, femstudy.fe.modal).
"""

from __future__ import annotations

import hashlib
import logging
import struct
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np
import scipy.sparse as sp

from femstudy.atomic import atomic_path
from femstudy.fe.linsolve import Factor, compressed
from femstudy.fe.subspace import orthonormal_complement

log = logging.getLogger(__name__)

#: Largest bound on ‖K x − b‖ / ‖b‖ at which a kept combination serves b. A direct solve
#: leaves 1e-10 to 1e-9 of the right-hand side here; a force 1e-8 of the load moves the
#: model far less than the transient's accepted error indicator (femstudy.fe.transient).
RTOL = 1e-8
#: Directions of a right-hand side below this fraction of its norm are not solved for: they
#: are round-off of directions already kept, well inside the bound's RTOL.
NEGLIGIBLE = 1e-10
#: Most pairs kept for one matrix (the default femur's study keeps 76 global pairs: 215 MB).
MAX_KEPT = 160
#: Largest set stored [bytes]: a finer mesh's set would fill the disk faster than it saves time.
MAX_STORED_BYTES = 2 ** 30


def fingerprint(A: sp.csr_matrix | sp.bsr_matrix) -> str:
    """SHA-256 of a CSR or BSR matrix's shape, block size, pattern and values (its sorted-index
    form), each array hashed as stored with its type (no 64-bit copies: 0.1–0.2 s less per K_ff
    of the femur; no CSR copy of a BSR K_ff: 0.2 s less). The same matrix stored as CSR and as
    BSR has two fingerprints: a model's K_ff always comes in the same one."""
    A = compressed(A)
    if not A.has_sorted_indices:
        A = A.sorted_indices()
    blocks = A.blocksize if A.format == "bsr" else ()
    digest = hashlib.sha256(np.array(A.shape + blocks, np.int64).tobytes())
    for part in (A.indptr, A.indices, A.data):
        digest.update(part.dtype.str.encode())
        digest.update(np.ascontiguousarray(part).data)
    return digest.hexdigest()[:32]


def read_store(path: Path, names, what: str) -> dict | None:
    """The arrays ``names`` of the store at ``path``; None when there is none or it cannot be
    read (logged: a damaged store costs a recomputation, never the run). Every reader checks
    what it reads against its model before using it."""
    if not path.is_file():
        return None
    try:
        with zipfile.ZipFile(path) as store, open(path, "rb") as raw:
            return {name: _member(store, raw, f"{name}.npy") for name in names}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        log.warning("ignoring unreadable kept %s %s (%s)", what, path, exc)
        return None


def _member(store: zipfile.ZipFile, raw, name: str) -> np.ndarray:
    """One array of an ``np.savez`` file. Its members are stored uncompressed: the array is read
    straight from the file at the member's data (its local header is 30 bytes, then the name
    and an extra field), one copy from the page cache. Through ``np.load`` the zip module reads
    it in 256 kB pieces, checksummed and copied twice: 0.16–0.46 s against 0.07 s for the
    default study's 205 MB of kept solutions, in a fresh process."""
    info = store.getinfo(name)
    if info.compress_type != zipfile.ZIP_STORED:
        with store.open(info) as member:
            return np.lib.format.read_array(member, allow_pickle=False)
    raw.seek(info.header_offset)
    header = raw.read(30)
    if header[:4] != b"PK\x03\x04":
        raise zipfile.BadZipFile(f"no local header for {name}")
    name_length, extra_length = struct.unpack("<HH", header[26:30])
    raw.seek(info.header_offset + 30 + name_length + extra_length)
    return np.lib.format.read_array(raw, allow_pickle=False)


def write_store(path: Path, what: str, **arrays) -> bool:
    """Store ``arrays`` at ``path`` atomically; False (logged) when the folder cannot take it:
    a read-only or full cache costs the next run a recomputation, not this run."""
    try:
        with atomic_path(path) as tmp, open(tmp, "wb") as out:
            np.savez(out, **arrays)
        return True
    except OSError as exc:
        log.warning("could not keep the %s in %s (%s)", what, path.parent, exc)
        return False


class KeptSolutions(Factor):
    """K⁻¹ from kept solutions of the same K, factorising only for right-hand sides they miss.

    A : the SPD matrix (CSR, or BSR of node blocks), K_ff of a model
    factorize : makes the solver of A when a right-hand side is missed (e.g. ``lambda:
        linsolve.factorize(A, "auto")``)
    folder : where the set is stored (``<fingerprint>.npz``), read at creation and written
        by :meth:`close` when it grew
    """

    def __init__(self, A: sp.spmatrix, factorize: Callable[[], Factor], folder: Path):
        super().__init__(A)
        self.A = compressed(A)
        self.path = Path(folder) / f"{fingerprint(self.A)}.npz"
        self._factorize, self._factor = factorize, None
        self.U, self.Z, self.e = np.zeros((self.n, 0)), np.zeros((self.n, 0)), np.zeros(0)
        self._room = None  # (U, Z) buffers of MAX_KEPT columns once the set grows
        self.loaded = self.served = 0  # pairs read from the store; right-hand sides served from kept pairs
        self._method, self._made = "", 0
        self._read()

    @property
    def method(self) -> str:
        """The solver that factorised A, else the one that made the kept solutions (with none
        kept, asking factorises: the method is only known then)."""
        return self._method or self._solver().method

    @property
    def factorisations(self) -> int:
        return self._made

    def _read(self) -> None:
        stored = read_store(self.path, ("U", "Z", "e", "method"), "solutions")
        if stored is None:
            return
        U, Z, e, method = stored["U"], stored["Z"], stored["e"], str(stored["method"])
        if U.shape != Z.shape or U.shape[0] != self.n or len(e) != U.shape[1] or U.shape[1] > MAX_KEPT:
            log.warning("ignoring kept solutions %s: they do not fit a %d-unknown matrix", self.path, self.n)
            return
        # on random combinations w: U orthonormal (‖U w‖ = ‖w‖) and K Z w = U w within the kept residuals
        w = np.random.default_rng().standard_normal((U.shape[1], 2))
        Uw, size = U @ w, np.linalg.norm(w, axis=0)
        misfit = np.linalg.norm(self.A @ (Z @ w) - Uw, axis=0)
        if np.any(np.abs(np.linalg.norm(Uw, axis=0) - size) > 1e-10 * size) or \
                np.any(misfit > 2 * np.abs(w).T @ e + RTOL * size):
            log.warning("ignoring kept solutions %s: they fail the check against this matrix", self.path)
            return
        self.U, self.Z, self.e, self._method = U, Z, e, method
        self.loaded = len(e)
        log.info("%d kept solutions of this %s-unknown matrix serve its solves (%s)", self.loaded,
                 f"{self.n:,}", self.path.name[:12])

    def _solve(self, b, x0):
        B = b.reshape(self.n, -1)
        C, served = self._combination(B)
        if served:
            self.served += B.shape[1]
            return (self.Z @ C).reshape(b.shape)
        if len(self.e) + B.shape[1] <= MAX_KEPT:
            self._add(B)
            C, served = self._combination(B)
            if served:
                return (self.Z @ C).reshape(b.shape)
        return self._solver().solve(b, x0)  # the set is full, or (never seen) its grown combination fails the bound

    def _combination(self, B: np.ndarray) -> tuple[np.ndarray, bool]:
        """C = UᵀB, and whether x = Z C meets the residual bound for every column of B."""
        C = self.U.T @ B
        bound = np.linalg.norm(B - self.U @ C, axis=0) + np.abs(C).T @ self.e
        return C, bool(np.all(bound <= RTOL * np.linalg.norm(B, axis=0)))

    def _solver(self) -> Factor:
        if self._factor is None:
            self._factor = self._factorize()
            self._method, self._made = self._factor.method, self._made + 1
        return self._factor

    def _add(self, B: np.ndarray) -> None:
        """Solve for the directions of B outside span(U) and keep them."""
        norms = np.linalg.norm(B, axis=0)
        Q = orthonormal_complement(self.U, B / np.where(norms > 0, norms, 1.0), NEGLIGIBLE)
        if Q.shape[1] == 0:
            return
        # a direction of singular value σ is orthogonal to U only to ~1e-16/σ: once more, then
        # orthonormalise (a right-hand side kept by another run differs from this run's by
        # round-off, so nearly-in-span directions of σ ~ 1e-8 do occur)
        Q = np.linalg.qr(Q - self.U @ (self.U.T @ Q))[0]
        X = self._solver().solve(Q)
        X = X.reshape(Q.shape)
        residual = np.linalg.norm(self.A @ X - Q, axis=0)
        r, k = len(self.e), Q.shape[1]
        if self._room is None:  # column-major: memory only for the columns written, no copy as the set grows
            self._room = tuple(np.empty((self.n, MAX_KEPT), order="F") for _ in range(2))
            self._room[0][:, :r], self._room[1][:, :r] = self.U, self.Z
        self._room[0][:, r:r + k], self._room[1][:, r:r + k] = Q, X
        self.U, self.Z = self._room[0][:, :r + k], self._room[1][:, :r + k]
        self.e = np.concatenate([self.e, residual])

    def close(self) -> None:
        """Store the set when it grew (atomically, beside other processes' sets), then release
        the factorisation."""
        size = self.U.nbytes + self.Z.nbytes
        if self.U.shape[1] > self.loaded and size > MAX_STORED_BYTES:
            log.info("the solutions of this %s-unknown matrix are not kept: %.1f GB is more than %.1f GB",
                     f"{self.n:,}", size / 1e9, MAX_STORED_BYTES / 1e9)
        elif self.U.shape[1] > self.loaded and write_store(self.path, "solutions", U=self.U, Z=self.Z, e=self.e,
                                                           method=self.method):
            self.loaded = self.U.shape[1]
        if self._factor is not None:
            self._factor.close()
            self._factor = None

    def describe(self) -> str:
        if self._factor is not None:
            return self._factor.describe()
        return f"{self.method}: {self.n:,} unknowns, no factorisation ({self.served} solves from kept solutions)"
