"""Verification models for the FE tests: structured tubes, their loads and beam theory.

Models are cached per process so several tests share one assembly. Material: the thesis's
cortical bone (E = 16 GPa, ν = 0.4, ρ = 1700 kg/m³), the default of BoneMaterials.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.linalg
import skfem

from femstudy.materials import BoneMaterials
from femstudy.fe import assemble, fix_facets
from femstudy.fe.geometry import tube_mesh

E_MPA, NU, RHO = 16e3, 0.4, 1700e-12
G_MPA = E_MPA / (2 * (1 + NU))
#: A slender tube (L/D ≈ 21) so that 3D end effects stay below the 2 % bending tolerance.
LENGTH, R_OUT, R_IN = 600.0, 14.0, 6.5


@lru_cache(maxsize=None)
def tube(n_radial: int, n_around: int, n_along: int, order: int, length: float = LENGTH):
    return assemble(tube_mesh(length, R_OUT, R_IN, n_radial, n_around, n_along), BoneMaterials(), order=order)


def end_facets(system, z: float) -> np.ndarray:
    """Boundary facets lying in the plane z = const."""
    facets = system.mesh.boundary_facets()
    return facets[(np.abs(system.mesh.p[2, system.mesh.facets[:, facets]] - z) < 1e-9).all(axis=0)]


def clamped_both_ends(system, length: float = LENGTH):
    return fix_facets(system, np.concatenate([end_facets(system, 0.0), end_facets(system, length)]))


def mid_slice_load(system, width: float, length: float = LENGTH) -> np.ndarray:
    """A 1 N transverse (y) load spread as a uniform body force over the elements whose
    centroids lie within width/2 of mid-span: f_i = ∫ N_i b dV, Σ f_y = 1."""
    centroid_z = system.mesh.p[2, system.mesh.t].mean(axis=0)
    cells = np.flatnonzero(np.abs(centroid_z - length / 2) < width / 2)
    basis = skfem.Basis(system.mesh, skfem.ElementVector(system.ref.element), elements=cells)
    f = skfem.asm(skfem.LinearForm(lambda v, w: v[1]), basis)
    return f / f[1::3].sum()


def cowper_shear_coefficient(nu: float, ratio: float) -> float:
    """Timoshenko shear coefficient of a hollow circular section, inner/outer radius
    ``ratio`` (Cowper 1966): κ = 6(1+ν)(1+m²)² / ((7+6ν)(1+m²)² + (20+12ν)m²)."""
    a = (1 + ratio ** 2) ** 2
    return 6 * (1 + nu) * a / ((7 + 6 * nu) * a + (20 + 12 * nu) * ratio ** 2)


def _clamped_green(x, a, length):
    """Euler–Bernoulli deflection at x of a clamped–clamped beam (EI = 1) under a unit
    load at a: b²x²(3aL − (3a + b)x)/(6L³) for x ≤ a, b = L − a; mirrored for x > a."""
    x, a = np.broadcast_arrays(x, a)
    flip = x > a
    x, a = np.where(flip, length - x, x), np.where(flip, length - a, a)
    b = length - a
    return b * b * x * x * (3 * a * length - (3 * a + b) * x) / (6 * length ** 3)


def timoshenko_slice_deflection(EI: float, kGA: float, width: float, length: float = LENGTH, n: int = 801):
    """Load-averaged mid-span deflection (1/P)∫q w dx of a clamped–clamped Timoshenko beam
    under a unit load spread uniformly over the central ``width``. For symmetric loads the
    bending moments are Euler–Bernoulli's and the shear part is w_s' = V/(κGA)."""
    s = np.linspace((length - width) / 2, (length + width) / 2, n)
    q = np.full(n, 1.0 / (n - 1))
    q[[0, -1]] /= 2  # trapezoidal weights of the unit load
    bending = q @ _clamped_green(s[:, None], s[None, :], length) @ q / EI
    x = np.minimum(s, length - s)
    x0 = (length - width) / 2
    shear = q @ np.where(x < x0, x / 2, x0 / 2 + (x - x0) / 2 - (x - x0) ** 2 / (2 * width)) / kGA
    return bending + shear


def timoshenko_frequencies(EI: float, kGA: float, rhoA: float, rhoI: float, k: int = 2,
                           length: float = LENGTH, n: int = 600) -> np.ndarray:
    """Lowest k bending frequencies [Hz] of a clamped–clamped Timoshenko beam (shear and
    rotary inertia), from n linear elements with one-point shear integration: converged to
    < 1e-4 at n = 600, far inside the 3 % tolerance it is compared with."""
    h = length / n
    b = np.array([-1 / h, -0.5, 1 / h, -0.5])  # shear strain w' − θ at the element centre
    ke = EI / h * np.array([[0, 0, 0, 0], [0, 1, 0, -1], [0, 0, 0, 0], [0, -1, 0, 1]]) + kGA * h * np.outer(b, b)
    line = h / 6 * np.array([[2, 1], [1, 2]])
    me = np.zeros((4, 4))
    me[np.ix_([0, 2], [0, 2])] = rhoA * line
    me[np.ix_([1, 3], [1, 3])] = rhoI * line
    K = np.zeros((2 * n + 2, 2 * n + 2))
    M = np.zeros_like(K)
    for e in range(n):
        K[2 * e:2 * e + 4, 2 * e:2 * e + 4] += ke
        M[2 * e:2 * e + 4, 2 * e:2 * e + 4] += me
    free = np.arange(2, 2 * n)
    w2 = scipy.linalg.eigh(K[np.ix_(free, free)], M[np.ix_(free, free)], eigvals_only=True,
                           subset_by_index=[0, k - 1])
    return np.sqrt(w2) / (2 * np.pi)
