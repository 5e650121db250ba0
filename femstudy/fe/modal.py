"""Natural frequencies and mode shapes: K φ = ω² M φ on the free DOFs.

Shift-invert Lanczos (ARPACK through ``scipy.sparse.linalg.eigsh``) about σ = 0 finds the
lowest modes; the operator (K − σM)⁻¹ = K_ff⁻¹ reuses the cached stiffness factorisation.
With K in N/mm and M in tonne, ω² comes out in 1/s².
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse.linalg import LinearOperator, eigsh

from femstudy.errors import require
from femstudy.fe.static import reduced, stiffness_factor


@dataclass(frozen=True)
class Modes:
    """frequency_Hz (k,), ascending; shapes (n_dofs, k) M-orthonormal, zero on the clamps."""

    frequency_Hz: np.ndarray
    shapes: np.ndarray

    @property
    def period_s(self) -> np.ndarray:
        return 1.0 / self.frequency_Hz


def solve_modal(system, bc, k: int = 6, method: str = "auto", console=None) -> Modes:
    """The lowest ``k`` natural frequencies [Hz] and mode shapes of the clamped model."""
    require(1 <= k < len(bc.free), f"cannot compute {k} modes of a model with {len(bc.free)} free DOFs")
    factor = stiffness_factor(system, bc, method, console)
    n = len(bc.free)
    inverse = LinearOperator((n, n), matvec=factor.solve, dtype=float)
    omega2, phi = eigsh(reduced(system, bc, "K"), k=k, M=reduced(system, bc, "M"), sigma=0.0,
                        which="LM", OPinv=inverse)
    order = np.argsort(omega2)
    omega2, phi = omega2[order], phi[:, order]
    if console is not None:
        console.progress("natural frequencies: " + ", ".join(f"{f:.1f}" for f in np.sqrt(omega2) / (2 * np.pi)) + " Hz")
    return Modes(np.sqrt(np.maximum(omega2, 0.0)) / (2 * np.pi), bc.expand(phi))
