"""Spherical caps on a triangulated surface: least-squares sphere fit and detection.

* :func:`fit_sphere`: the algebraic (Kåsa) least-squares sphere. A point x on a sphere of
  centre c and radius r satisfies |x|² = 2 c·x + k with k = r² − |c|², which is linear in
  (c, k); solved with area weights, then r = √(k + |c|²).
* :func:`find_sphere`: the best spherical cap among oriented surface samples. Every sample
  votes for the centres x − ρ n it would have if it lay on a sphere of radius ρ (n the
  outward normal), for ρ over the plausible radii; votes are area-weighted and binned on a
  grid. Each of the most-voted bins seeds a refit that keeps the samples whose distance to
  the centre is within ``band`` × r of the radius and whose normal points away from the
  centre within ``cone_deg``, until the kept set settles. The cap with the largest
  *coverage* — kept area over the whole sphere's area 4πr² — wins: a femoral head shows
  0.46-0.87 of its sphere, the best cap at a knee 0.15-0.39 (docs/meshing.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SphereFit:
    """A spherical cap found on a surface [the samples' length unit].

    centre   : (3,) centre of the sphere
    radius   : radius
    rms      : root-mean-square radial residual of the kept samples (area-weighted)
    coverage : area of the kept samples over the sphere's area 4πr² (0-1)
    """

    centre: np.ndarray
    radius: float
    rms: float
    coverage: float

    def summary(self, digits: int = 1) -> dict:
        """Centre, radius, rms and coverage as plain, rounded numbers (for reports)."""
        return {"centre": [round(float(v), digits) for v in self.centre], "radius": round(self.radius, digits),
                "rms": round(self.rms, digits + 1), "coverage": round(self.coverage, 2)}


def fit_sphere(points: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Least-squares sphere through ``points`` (n, 3), optionally weighted; returns (centre, radius).

    Solves |x|² = 2 c·x + k in the least-squares sense (k = r² − |c|²).

    Examples
    --------
    >>> import numpy as np
    >>> u = np.random.default_rng(0).normal(size=(200, 3))
    >>> centre, radius = fit_sphere(5 + 2 * u / np.linalg.norm(u, axis=1, keepdims=True))
    >>> bool(np.allclose(centre, 5) and np.isclose(radius, 2))
    True
    """
    x = np.asarray(points, float)
    w = np.ones(len(x)) if weights is None else np.sqrt(np.asarray(weights, float))
    A = np.column_stack([2 * x, np.ones(len(x))]) * w[:, None]
    b = (x ** 2).sum(axis=1) * w
    solution, *_ = np.linalg.lstsq(A, b, rcond=None)
    centre = solution[:3]
    return centre, float(np.sqrt(max(solution[3] + centre @ centre, 0.0)))


def find_sphere(centres: np.ndarray, normals: np.ndarray, areas: np.ndarray, radius_range: tuple[float, float],
                cell: float, band: float = 0.06, cone_deg: float = 25.0, max_samples: int = 20_000,
                seeds: int = 6) -> SphereFit | None:
    """The spherical cap covering the largest share of its sphere among surface samples.

    Parameters
    ----------
    centres, normals, areas
        Sample positions (n, 3), unit outward normals (n, 3) and areas (n,).
    radius_range
        Smallest and largest radius searched; a refit ending outside it is discarded.
    cell
        Size of the voting grid's bins (and twice the radius step), in the samples' unit.
    band, cone_deg
        A sample is kept if its distance to the centre is within ``band`` × r of r and its
        normal is within ``cone_deg`` of the direction away from the centre.
    max_samples, seeds
        Beyond this many samples an even stride of them is used, their areas scaled up to
        match; this many distinct top bins are refitted.

    Returns
    -------
    SphereFit or None
        None when no seed keeps at least 20 samples inside ``radius_range``.

    Examples
    --------
    >>> import pyvista as pv
    >>> s = pv.Sphere(radius=20, center=(1, 2, 3), theta_resolution=60, phi_resolution=60)
    >>> s = s.compute_cell_sizes().compute_normals(cell_normals=True, point_normals=False)
    >>> fit = find_sphere(s.cell_centers().points, s.cell_data["Normals"], s.cell_data["Area"], (10, 30), 2.0)
    >>> round(fit.radius), fit.coverage > 0.95
    (20, True)
    """
    step = max(1, -(-len(centres) // max_samples))
    x, n = np.asarray(centres, float)[::step], np.asarray(normals, float)[::step]
    a = np.asarray(areas, float)[::step] * step
    r_lo, r_hi = radius_range
    if len(x) < 20:
        return None
    radii = np.arange(r_lo, r_hi + 1e-9 * r_hi, cell / 2)
    votes = (x[None] - radii[:, None, None] * n[None]).reshape(-1, 3)
    weights = np.tile(a, len(radii))
    bins = np.floor(votes / cell).astype(np.int64)
    origin = bins.min(axis=0)
    shape = bins.max(axis=0) - origin + 1
    flat = np.ravel_multi_index((bins - origin).T, shape)
    tally = np.bincount(flat, weights=weights)
    radius_sum = np.bincount(flat, weights=weights * np.repeat(radii, len(x)))
    top = np.argsort(tally)[::-1][:50 * seeds]
    best, tried = None, []
    for k, index in zip(top, np.column_stack(np.unravel_index(top, shape))):
        if len(tried) == seeds:
            break
        if any(np.abs(index - t).max() <= 1 for t in tried):
            continue  # a neighbour of a bin already refitted: the same cap
        tried.append(index)
        centre = (index + origin + 0.5) * cell
        near = np.linalg.norm(x - centre, axis=1) < 1.5 * r_hi  # the refit stays near its seed
        fit = _refit(x[near], n[near], a[near], centre, radius_sum[k] / tally[k], band, cone_deg)
        if fit is not None and r_lo <= fit.radius <= r_hi and (best is None or fit.coverage > best.coverage):
            best = fit
    return best


def _refit(x, n, a, centre, radius, band, cone_deg, iterations: int = 12) -> SphereFit | None:
    """Alternately keep the samples on the sphere and refit it to them, until the kept set settles."""
    cos_cone = np.cos(np.radians(cone_deg))
    kept = np.zeros(len(x), bool)
    for _ in range(iterations):
        d = x - centre
        dist = np.linalg.norm(d, axis=1)
        now = (np.abs(dist - radius) < band * radius) & (np.einsum("ij,ij->i", d, n) > cos_cone * dist)
        if now.sum() < 20:
            return None
        if np.array_equal(now, kept):
            break
        kept = now
        centre, radius = fit_sphere(x[kept], a[kept])
    residual = np.linalg.norm(x[kept] - centre, axis=1) - radius
    rms = float(np.sqrt(np.average(residual ** 2, weights=a[kept])))
    return SphereFit(centre, float(radius), rms, float(a[kept].sum() / (4 * np.pi * radius ** 2)))
