"""Structured tetrahedral meshes of simple solids, for verification against beam theory.

A hollow circular tube is meshed on an (r, θ, z) grid: every grid hexahedron is split into
six tetrahedra along its main diagonal (Kuhn's subdivision), which is conforming because all
hexahedra use the same split. The polygonal cross-section is inscribed in the circles
(n_around straight chords): :func:`polygon_section` gives its exact area and moments.
"""

from __future__ import annotations

from itertools import permutations

import numpy as np

from femstudy.femur_mesh import CORTICAL, TetMesh


def _kuhn() -> np.ndarray:
    """The six tetrahedra of the unit cube along its diagonal: for each ordering of the axes,
    the path (0,0,0) → … → (1,1,1) stepping one axis at a time; corner (a, b, c) is 4a+2b+c."""
    tets = []
    for axes in permutations(range(3)):
        corner, path = np.zeros(3, dtype=int), [0]
        for axis in axes:
            corner[axis] = 1
            path.append(4 * corner[0] + 2 * corner[1] + corner[2])
        tets.append(path)
    return np.array(tets)


KUHN = _kuhn()


def tube_mesh(length_mm: float, outer_radius_mm: float, inner_radius_mm: float, n_radial: int, n_around: int,
              n_along: int, region: int = CORTICAL) -> TetMesh:
    """A hollow tube along z, from z = 0 to ``length_mm``, centred on the z axis [mm]."""
    r = np.linspace(inner_radius_mm, outer_radius_mm, n_radial + 1)
    theta = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    z = np.linspace(0.0, length_mm, n_along + 1)
    R, T, Z = np.meshgrid(r, theta, z, indexing="ij")
    points = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(), Z.ravel()])

    def index(i, j, k):
        return (i * n_around + j % n_around) * (n_along + 1) + k

    i, j, k = np.meshgrid(np.arange(n_radial), np.arange(n_around), np.arange(n_along), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    corners = np.stack([index(i + a, j + b, k + c) for a in (0, 1) for b in (0, 1) for c in (0, 1)], axis=1)
    tets = corners[:, KUHN].reshape(-1, 4)
    p = points[tets]
    det = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    tets[det < 0] = tets[det < 0][:, [0, 2, 1, 3]]
    return TetMesh(points, tets.astype(np.int64), np.full(len(tets), region, dtype=np.int8))


def polygon_section(outer_radius_mm: float, inner_radius_mm: float, n_around: int) -> dict:
    """Area A [mm²], second moment I about a diameter through a vertex [mm⁴] and polar
    moment J = 2I [mm⁴] of the annulus between two regular n-gons inscribed in the circles.
    A regular n-gon (n ≥ 3) of circumradius R has A = n R² sin(2π/n)/2 and
    I = n R⁴ sin(2π/n) (2 + cos(2π/n))/24 about every axis through its centre (the sum of its
    n centre triangles' polar moments (A/6)(|a|² + |b|² + a·b), halved)."""
    s, c = np.sin(2 * np.pi / n_around), np.cos(2 * np.pi / n_around)
    area = n_around * s / 2 * (outer_radius_mm ** 2 - inner_radius_mm ** 2)
    inertia = n_around * s * (2 + c) / 24 * (outer_radius_mm ** 4 - inner_radius_mm ** 4)
    return {"A": area, "I": inertia, "J": 2 * inertia}
