"""Natural frequencies and mode shapes: K φ = ω² M φ on the free DOFs.

Block shift-invert Krylov about σ = 0 with Rayleigh–Ritz: the space spanned by a block X0 of
k + 2 vectors and K⁻¹M X0, (K⁻¹M)² X0, … (each block one multi-column solve with the study's
factorisation of K_ff) is projected, and the lowest k Ritz pairs are accepted when every
residual ‖Kφ − ω²Mφ‖ is below 1e-6 of ‖Kφ‖ (the frequency, a Rayleigh quotient, is then
exact to ~1e-12).
ARPACK's shift-invert Lanczos (``scipy.sparse.linalg.eigsh``) needs the same factorisation
but one single-vector solve per step, about 30 for 6 modes of the femur; the block method
needs 3–5 block solves. With K in N/mm and M in tonne, ω² comes out in 1/s².

With kept solutions (:func:`femstudy.fe.factorize` with ``keep``), the modes are kept too,
beside them: an analysis of the same K_ff and M_ff (their fingerprints) for the same number of
modes reads the pairs back and uses them when they pass what a converged analysis passes (every
residual within rtol, each ω² its shape's Rayleigh quotient, ΦᵀMΦ = I to 1e-8); otherwise it
computes and stores them.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.linalg

from femstudy.errors import require
from femstudy.fe import linsolve
from femstudy.fe.kept import KeptSolutions, fingerprint, read_store, write_store
from femstudy.fe.static import FactorizedSystem
from femstudy.fe.subspace import grow_projection, orthonormal_complement, symmetric

log = logging.getLogger(__name__)

#: Relative change of the Ritz values between blocks below which the residuals are checked.
RITZ_SETTLED = 1e-9
#: Largest relative residual of a mode accepted when the iteration stops short of ``rtol``.
LARGEST_RESIDUAL = 1e-4
#: Largest ‖ΦᵀMΦ − I‖ (entries) of kept mode shapes that are used.
KEPT_ORTHONORMALITY = 1e-8
#: Largest |φᵀKφ/φᵀMφ − ω²| / max ω² of kept modes that are used: Ritz values are their
#: vectors' Rayleigh quotients to round-off (1.3e-11 on the default femur), while the residual
#: test alone would pass an ω² off by up to rtol.
KEPT_RAYLEIGH = 1e-9


@dataclass(frozen=True)
class Modes:
    """frequency_Hz (k,), ascending; shapes (n_dofs, k) M-orthonormal, zero on the clamps;
    kept: read back from an earlier analysis of the same matrices (module docstring)."""

    frequency_Hz: np.ndarray
    shapes: np.ndarray
    kept: bool = False

    @property
    def period_s(self) -> np.ndarray:
        return 1.0 / self.frequency_Hz


def solve_modal(fs: FactorizedSystem, k: int = 6, rtol: float = 1e-6, max_blocks: int = 20) -> Modes:
    """The lowest natural frequencies [Hz] and mode shapes of the clamped model.

    Parameters
    ----------
    fs : FactorizedSystem
        Its K_ff factorisation is the shift-invert operator.
    k : int
        Number of modes.
    rtol : float
        Largest relative residual ‖Kφ − ω²Mφ‖ / ‖Kφ‖ accepted.

    Returns
    -------
    Modes
    """
    n = fs.n_free
    require(1 <= k < n, f"cannot compute {k} modes of a model with {n} free DOFs")
    store = _kept_path(fs, k)
    kept = None if store is None else _read_kept(fs, store, k, rtol)
    if kept is not None:
        omega2, phi = kept
    else:
        with linsolve.one_openblas_thread():  # its substitutions follow dense products
            omega2, phi = _block_krylov(fs, k, rtol, max_blocks)
        if store is not None:
            write_store(store, "modes", omega2=omega2, phi=phi)
    frequencies = np.sqrt(np.maximum(omega2, 0.0)) / (2 * np.pi)
    log.info("natural frequencies: %s Hz%s", ", ".join(f"{f:.1f}" for f in frequencies),
             " (kept from an earlier analysis of this model)" if kept is not None else "")
    return Modes(frequencies, fs.bc.expand(phi), kept is not None)


def _block_krylov(fs: FactorizedSystem, k: int, rtol: float, max_blocks: int) -> tuple[np.ndarray, np.ndarray]:
    """The lowest k Ritz pairs (ω² [1/s²], φ on the free DOFs) of the block shift-invert Krylov space."""
    n = fs.n_free
    block = min(k + 2, n - 1)
    X = np.random.default_rng(0).standard_normal((n, block))
    space = np.empty((n, min(n, max_blocks * block)), order="F")  # the basis grows in place, column-major
    V = space[:, :0]
    Kr = Mr = np.zeros((0, 0))
    previous, phi, residual = np.full(k, np.inf), None, None
    for _ in range(max_blocks):
        Q = orthonormal_complement(V, X)
        if Q.shape[1] == 0:
            break
        phi = residual = None  # of the basis before this block
        KQ, MQ = fs.stiffness_times(Q), fs.mass(Q)
        m = V.shape[1]
        space[:, m:m + Q.shape[1]] = Q
        V = space[:, :m + Q.shape[1]]
        Kr, Mr = grow_projection(Kr, V, KQ, Q.shape[1]), grow_projection(Mr, V, MQ, Q.shape[1])
        omega2, Phi = scipy.linalg.eigh(symmetric(Kr), symmetric(Mr))
        omega2, Phi = omega2[:k], Phi[:, :k]
        # a Ritz value's error is of the order of its vector's residual squared: until the
        # values settle to RITZ_SETTLED the residuals cannot be below rtol, and are not computed
        settled = np.all(np.abs(omega2 - previous) <= RITZ_SETTLED * np.abs(omega2))
        previous = omega2
        if settled:
            phi = V @ Phi
            residual = _residuals(fs.stiffness_times(phi), fs.mass(phi), omega2)
            if residual.max() <= rtol:
                break
        if V.shape[1] + block > n:
            break
        X = fs.factor.solve(MQ)
    if residual is None:
        phi = V @ Phi
        residual = _residuals(fs.stiffness_times(phi), fs.mass(phi), omega2)
    require(residual.max() <= max(rtol, LARGEST_RESIDUAL), f"the lowest {k} modes did not converge (relative residual "
                                               f"{residual.max():.1e} after {V.shape[1]} vectors)")
    return omega2, phi


def _residuals(stiffness: np.ndarray, mass: np.ndarray, omega2: np.ndarray) -> np.ndarray:
    """‖Kφ − ω²Mφ‖ / ‖Kφ‖ of each pair, from the products Kφ and Mφ."""
    return np.linalg.norm(stiffness - mass * omega2, axis=0) / np.linalg.norm(stiffness, axis=0)


def _kept_path(fs: FactorizedSystem, k: int) -> Path | None:
    """Where the k modes of fs's K_ff and M_ff are kept: beside its kept solutions, if any.
    M_ff is named by what it is made of, the nodal mass and the free DOFs (M = M_nodes ⊗ I₃
    restricted to them), so that finding the modes does not form it (1 s at 8 mm)."""
    if not isinstance(fs.factor, KeptSolutions):
        return None
    mass = hashlib.sha256(fingerprint(fs.system.M_nodes).encode())
    mass.update(np.ascontiguousarray(fs.bc.free, dtype=np.int64).data)
    return fs.factor.path.with_name(f"{fs.factor.path.stem}-modes{k}-{mass.hexdigest()[:16]}.npz")


def _read_kept(fs: FactorizedSystem, path: Path, k: int, rtol: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Kept (ω², φ) that fit fs and pass the checks a converged analysis passes, else None:
    residuals within ``rtol``, each ω² its shape's Rayleigh quotient to :data:`KEPT_RAYLEIGH`
    (as a Ritz value is), ascending, and ΦᵀMΦ = I to :data:`KEPT_ORTHONORMALITY`."""
    stored = read_store(path, ("omega2", "phi"), "modes")
    if stored is None:
        return None
    omega2, phi = stored["omega2"], stored["phi"]
    if omega2.shape != (k,) or phi.shape != (fs.n_free, k):
        log.warning("ignoring kept modes %s: they do not fit this model", path)
        return None
    stiffness, mass = fs.stiffness_times(phi), fs.mass(phi)
    residual = _residuals(stiffness, mass, omega2)
    rayleigh = np.einsum("ik,ik->k", phi, stiffness) / np.einsum("ik,ik->k", phi, mass)
    if (residual.max() > rtol or np.abs(rayleigh - omega2).max() > KEPT_RAYLEIGH * omega2.max()
            or np.abs(phi.T @ mass - np.eye(k)).max() > KEPT_ORTHONORMALITY or np.any(np.diff(omega2) < 0)):
        log.warning("ignoring kept modes %s: they fail the check against this model", path)
        return None
    return omega2, phi


