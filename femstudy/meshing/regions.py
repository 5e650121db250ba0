"""Cortical shell, medullary canal and cancellous bone derived from one outer surface.

Three scalar fields are sampled on a voxel grid (spacing ``VOXEL_MM``) around the bone,
each positive inside its region [mm]:

* ψ_B = depth below the outer surface (signed distance, exact to the sampling of the
  surface near it);
* ψ_I = ψ_B − t(s): inside the cortex's inner (endosteal) surface, where t(s) is the
  cortical thickness at fraction s of the length from the proximal end (:func:`thickness`);
* ψ_K: the medullary canal, K = I ∩ {p ≤ s ≤ d} ∖ J°, where J = the part of I in that span
  outside a tube of diameter ``canal.diameter_mm`` around the shaft's centreline (with
  rounded ends), and J° its morphological opening by a ball of diameter
  ``canal.min_cancellous_mm``.

So the canal is the requested tube where cancellous bone surrounds it (metaphyses), and
reaches out to the cortex where the cancellous layer around the tube would be thinner than
``min_cancellous_mm`` (the diaphysis): a sliver no mesh could resolve. The cortex is then
exactly t(s) thick at mid-shaft and the canal is as wide as the cortex leaves it (reported as
``canal_midshaft_diameter_mm``). Cancellous bone is I ∖ K: proximal above the canal's middle,
distal below it.

The zero level sets of ψ_I and ψ_K become triangle surfaces that TetWild meshes together
with the outer surface, so region boundaries are faces of the tet mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from femstudy.errors import UserError
from femstudy.meshing.frame import Frame
from femstudy.meshing.surface import Surface

VOXEL_MM = 1.0
#: Fractions of the length over which the cortex thins from mid-shaft to epiphysis thickness,
#: measured outwards from the canal's ends: full thickness from 0.1 inside the canal's span,
#: epiphysis thickness from 0.1 beyond it.
THINNING_SPAN = 0.1


def thickness(s, cortex, canal) -> np.ndarray:
    """Cortical thickness t(s) [mm]: ``midshaft_mm`` along the diaphysis, ``epiphysis_mm`` at
    the ends, joined by a smoothstep S(u) = 3u² − 2u³ over ±``THINNING_SPAN`` around each canal end."""
    s = np.asarray(s, float)

    def ramp(u):
        u = np.clip(u, 0.0, 1.0)
        return u * u * (3 - 2 * u)

    p, d, w = canal.proximal_fraction, canal.distal_fraction, THINNING_SPAN
    full = np.minimum(ramp((s - (p - w)) / (2 * w)), ramp(((d + w) - s) / (2 * w)))
    return cortex.epiphysis_mm + (cortex.midshaft_mm - cortex.epiphysis_mm) * full


@dataclass
class RegionFields:
    """ψ_B, ψ_I, ψ_K on a regular grid (origin, spacing, dims in x, y, z; arrays indexed [i, j, k])."""

    origin: np.ndarray
    spacing: float
    depth: np.ndarray
    inner: np.ndarray
    canal: np.ndarray
    canal_axis: np.ndarray  # (n, 3) centreline points from proximal to distal end of the canal

    def sample(self, name: str, x: np.ndarray) -> np.ndarray:
        """Trilinear interpolation of field ``name`` at points x (n, 3); far outside: −1e3."""
        idx = ((np.asarray(x, float) - self.origin) / self.spacing).T
        return ndimage.map_coordinates(getattr(self, name), idx, order=1, mode="constant", cval=-1e3)

    def grid(self, name: str):
        """Field ``name`` as a pyvista ImageData point array named ``name``."""
        import pyvista as pv

        a = getattr(self, name)
        img = pv.ImageData(dimensions=a.shape, spacing=(self.spacing,) * 3, origin=self.origin)
        img[name] = a.ravel(order="F")
        return img


def _inside_mask(surf: Surface, origin, dims, h) -> np.ndarray:
    """Voxel centres inside the closed surface (VTK scan conversion), as a bool [i, j, k] array."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonCore import VTK_UNSIGNED_CHAR
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkImagingStencil import vtkImageStencil, vtkPolyDataToImageStencil

    stencil = vtkPolyDataToImageStencil()
    stencil.SetInputData(surf.polydata())
    stencil.SetOutputOrigin(*origin)
    stencil.SetOutputSpacing(h, h, h)
    stencil.SetOutputWholeExtent(0, dims[0] - 1, 0, dims[1] - 1, 0, dims[2] - 1)
    blank = vtkImageData()
    blank.SetDimensions(*dims)
    blank.SetSpacing(h, h, h)
    blank.SetOrigin(*origin)
    blank.AllocateScalars(VTK_UNSIGNED_CHAR, 1)
    vtk_to_numpy(blank.GetPointData().GetScalars())[:] = 0
    fill = vtkImageStencil()
    fill.SetInputData(blank)
    fill.SetStencilConnection(stencil.GetOutputPort())
    fill.ReverseStencilOn()
    fill.SetBackgroundValue(1)
    fill.Update()
    flat = vtk_to_numpy(fill.GetOutput().GetPointData().GetScalars())
    return flat.reshape(dims[::-1]).transpose(2, 1, 0).astype(bool)


def point_triangle_distance(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Euclidean distance from points p (n, 3) to triangles tri (n, 3, 3), pairwise.

    The closest point is found by the Voronoi-region tests of Ericson, *Real-Time Collision
    Detection* (2005), §5.1.5: a vertex, an edge or the face interior.
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    dot = lambda u, v: np.einsum("ij,ij->i", u, v)  # noqa: E731
    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp, cp = p - b, p - c
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 / (va + vb + vc)
        q = a + ab * (vb * denom)[:, None] + ac * (vc * denom)[:, None]  # face interior
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    cases = [
        (d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (d6 >= 0) & (d5 <= d6),
        (vc <= 0) & (d1 >= 0) & (d3 <= 0), (vb <= 0) & (d2 >= 0) & (d6 <= 0),
        (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0),
    ]
    points = [a, b, c, a + ab * t_ab[:, None], a + ac * t_ac[:, None], b + (c - b) * t_bc[:, None]]
    for case, point in zip(cases[::-1], points[::-1]):  # earlier tests take precedence
        q = np.where(case[:, None], point, q)
    return np.linalg.norm(p - q, axis=1)


def surface_distance(surf: Surface, x: np.ndarray, candidates: int = 8) -> np.ndarray:
    """Distance from points x to the surface: exact distance to the triangles whose centroids
    are the ``candidates`` nearest (a k-d tree), which contain the closest one in practice."""
    from scipy.spatial import cKDTree

    v = surf.points[surf.triangles]
    k = min(candidates, len(v))
    _, near = cKDTree(v.mean(axis=1)).query(x, k=k)
    best = np.full(len(x), np.inf)
    for j in range(k):
        best = np.minimum(best, point_triangle_distance(x, v[near[:, j]]))
    return best


def signed_depth(surf: Surface, origin, dims, h) -> np.ndarray:
    """Signed distance below the surface (positive inside) on the grid [mm].

    Euclidean distance transforms of the inside mask give it to about half a voxel; within
    two voxels of the surface it is replaced by the exact distance to the triangles.
    """
    inside = _inside_mask(surf, origin, dims, h)
    edt_in = ndimage.distance_transform_edt(inside, sampling=h)
    edt_out = ndimage.distance_transform_edt(~inside, sampling=h)
    depth = np.where(inside, edt_in - 0.5 * h, -(edt_out - 0.5 * h)).astype(np.float32)
    exact_where(surf, depth, origin, h, np.abs(depth) < 2 * h)
    return depth


def exact_where(surf: Surface, depth: np.ndarray, origin, h, mask: np.ndarray) -> None:
    """Replace ``depth`` by the exact signed distance where ``mask`` is set (sign kept)."""
    idx = np.nonzero(mask)
    x = origin + h * np.column_stack(idx)
    dist = surface_distance(surf, x)
    depth[idx] = np.where(depth[idx] > 0, dist, -dist)


def _centreline(frame: Frame, inside: np.ndarray, origin, h, span) -> np.ndarray:
    """Cross-section centroids of the bone at 1 % steps over ``span`` (fractions), fitted by a cubic."""
    idx = np.nonzero(inside)
    x = origin + h * np.column_stack(idx)
    s = frame.fraction(x)
    lo, hi = span
    bins = np.arange(lo, hi + 1e-9, 0.01)
    which = np.digitize(s, bins)
    cs, cx = [], []
    for b in range(1, len(bins)):
        sel = which == b
        if sel.sum() > 10:
            cs.append(0.5 * (bins[b - 1] + bins[b]))
            cx.append(x[sel].mean(axis=0))
    cs, cx = np.array(cs), np.array(cx)
    coef = np.polynomial.polynomial.polyfit(cs, cx, 3)
    return coef


def _keep_thick(mask: np.ndarray, thickness_mm: float, h: float) -> np.ndarray:
    """Morphological opening of ``mask`` by a ball of diameter ``thickness_mm`` (parts thinner
    than that vanish), without pieces smaller than 1 % of the largest one."""
    r = thickness_mm / 2
    if r > 0:
        eroded = ndimage.distance_transform_edt(mask, sampling=h) > r
        mask = ndimage.distance_transform_edt(~eroded, sampling=h) <= r
    labels, n = ndimage.label(mask)
    if n > 1:
        sizes = np.bincount(labels.ravel())[1:]
        mask = np.isin(labels, 1 + np.nonzero(sizes >= 0.01 * sizes.max())[0])
    return mask


def build_fields(surf_mm: Surface, frame: Frame, geometry, voxel_mm: float = VOXEL_MM) -> RegionFields:
    """ψ_B, ψ_I and ψ_K for a surface in mm and its frame (``geometry`` = case geometry section)."""
    cortex, canal = geometry.cortex, geometry.canal
    h = voxel_mm
    margin = 3 * h
    lo = surf_mm.points.min(axis=0) - margin
    hi = surf_mm.points.max(axis=0) + margin
    dims = np.ceil((hi - lo) / h).astype(int) + 1
    depth = signed_depth(surf_mm, lo, dims, h)
    ii, jj, kk = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in dims), indexing="ij", sparse=True)
    L = frame.length_mm
    up = frame.up.astype(np.float32)
    height = (lo @ frame.up) + h * (ii * up[0] + jj * up[1] + kk * up[2])
    s = (frame.top_mm - height) / L
    t = thickness(s, cortex, canal).astype(np.float32)
    exact_where(surf_mm, depth, lo, h, (np.abs(depth - t) < 2 * h) & (np.abs(depth) >= 2 * h))
    inner = depth - t
    if not (inner > 0).any():
        raise UserError(f"the cortex ({cortex.midshaft_mm:g} mm) fills the whole bone; "
                        "set a thinner geometry.cortex")

    p, d = canal.proximal_fraction, canal.distal_fraction
    coef = _centreline(frame, depth > 0, lo, h, (p - 0.02, d + 0.02))
    r = canal.diameter_mm / 2
    sp, sd = p + r / L, d - r / L  # centres of the rounded ends
    if sp >= sd:
        raise UserError(f"the canal span {p:g}-{d:g} is shorter than its diameter; widen it")
    sc = np.clip(s, sp, sd)
    centre = np.polynomial.polynomial.polyval(sc, coef)  # (3, ...) centreline point at clipped s
    gx = lo[0] + h * ii - centre[0]
    gy = lo[1] + h * jj - centre[1]
    gz = lo[2] + h * kk - centre[2]
    along = gx * up[0] + gy * up[1] + gz * up[2]
    dist_axis = np.sqrt(np.maximum(gx * gx + gy * gy + gz * gz - along * along, 0) + ((s - sc) * L) ** 2)
    tube = dist_axis < r
    slab = L * np.minimum(s - p, d - s)
    kept = _keep_thick(((inner > 0) & ~tube), canal.min_cancellous_mm, h)
    not_j = ndimage.distance_transform_edt(~kept, sampling=h) - ndimage.distance_transform_edt(kept, sampling=h)
    not_j = ndimage.gaussian_filter(not_j.astype(np.float32), 1.0)
    canal_field = np.minimum(np.minimum(inner, slab.astype(np.float32)), not_j)
    axis_s = np.linspace(p, d, 101)
    axis_pts = np.polynomial.polynomial.polyval(axis_s, coef).T
    return RegionFields(lo, h, depth, inner.astype(np.float32), canal_field.astype(np.float32), axis_pts)


def level_surface(fields: RegionFields, name: str, clip_by: str | None = None, clip_above: float = 0.0):
    """Zero level set of field ``name`` as triangles (optionally only where field ``clip_by`` >
    ``clip_above``), oriented towards the positive side's outside."""
    img = fields.grid(name)
    surf = img.contour([0.0], scalars=name, method="flying_edges")
    if surf.n_cells == 0:
        return surf
    if clip_by is not None:
        surf[clip_by] = fields.sample(clip_by, surf.points)
        surf = surf.clip_scalar(scalars=clip_by, value=clip_above, invert=False)
        surf = surf.extract_surface(algorithm=None)
    # contour points on grid nodes give collapsed triangles: drop them rather than keep them
    # as lines and points, which quadric decimation refuses (the LHDL CT femur has four)
    return surf.triangulate().clean(polys_to_lines=False, lines_to_points=False)
