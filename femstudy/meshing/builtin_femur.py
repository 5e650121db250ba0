"""The built-in adult left femur: an implicit shape, contoured and simplified to a small STL.

The bone is the zero level set of a signed-distance-like function f(x) (negative inside)
made of smooth unions of simple primitives: a bowed shaft of varying elliptical section with
a posterior ridge (linea aspera), a spherical head on a tapered neck, greater and lesser
trochanters, two distal condyles with the intercondylar notch and a trochlear groove.
f is sampled on a regular grid, contoured by VTK's flying edges, lightly smoothed and
decimated. Every step is deterministic, so the committed surface is regenerated bit for
bit; f is rounded to 1e-5 mm before contouring so that last-bit differences between
floating-point libraries do not change it.

Frame of the generated bone (mm, left femur in anatomical position): +z proximal with the
bottom of the condyles at z = 0 and the top of the head at z = ``length_mm``; +y anterior;
+x medial (towards the body's midline, i.e. the subject's right for a left femur).
"""

from __future__ import annotations

import hashlib
import math
import struct
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

#: The committed surface (``meshes/femur_left_medium.stl`` links to it).
BUILTIN_STL = Path(__file__).resolve().parent / "data" / "femur_left_medium.stl"


@dataclass(frozen=True)
class FemurParameters:
    """Anatomical parameters [mm, degrees]; the defaults describe a medium adult left femur.

    Dimensions not listed scale with ``length_mm / 455``.
    """

    length_mm: float = 455.0
    head_diameter_mm: float = 45.0
    neck_shaft_angle_deg: float = 130.0
    anteversion_deg: float = 12.0
    shaft_diameter_mm: float = 28.0
    bow_mm: float = 9.0
    offset_mm: float = 42.0
    resolution_mm: float = 1.0
    triangles: int = 12000

    def __post_init__(self):
        from femstudy.errors import require

        require(250 <= self.length_mm <= 650, f"length must lie in 250-650 mm, got {self.length_mm:g}")
        require(0.06 <= self.head_diameter_mm / self.length_mm <= 0.14,
                f"head diameter {self.head_diameter_mm:g} mm does not fit a {self.length_mm:g} mm femur "
                "(6-14 % of its length)")
        require(110 <= self.neck_shaft_angle_deg <= 150,
                f"neck-shaft angle must lie in 110-150 deg, got {self.neck_shaft_angle_deg:g}")
        require(-20 <= self.anteversion_deg <= 40, f"anteversion must lie in -20-40 deg, got {self.anteversion_deg:g}")
        require(0.04 <= self.shaft_diameter_mm / self.length_mm <= 0.09,
                f"shaft diameter {self.shaft_diameter_mm:g} mm does not fit a {self.length_mm:g} mm femur "
                "(4-9 % of its length)")
        require(0 <= self.bow_mm <= 25, f"anterior bow must lie in 0-25 mm, got {self.bow_mm:g}")
        require(0.06 <= self.offset_mm / self.length_mm <= 0.13,
                f"femoral offset {self.offset_mm:g} mm does not fit a {self.length_mm:g} mm femur")
        require(0.3 <= self.resolution_mm <= 3, f"resolution must lie in 0.3-3 mm, got {self.resolution_mm:g}")
        require(2000 <= self.triangles <= 200_000, f"triangles must lie in 2000-200000, got {self.triangles}")

    def digest(self) -> str:
        """A short hash of the parameters (stored in the STL header)."""
        text = ",".join(f"{k}={v!r}" for k, v in sorted(asdict(self).items()))
        return hashlib.sha256(text.encode()).hexdigest()[:16]


# -- signed-distance primitives (arrays of points p with shape (..., 3)) ---------------------

def _smin(a, b, k):
    """Polynomial smooth minimum (union) with blend width k [mm]."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def _smax(a, b, k):
    """Smooth maximum (intersection, or subtraction with -b)."""
    return -_smin(-a, -b, k)


def _ellipsoid(p, centre, radii):
    """Approximate signed distance to an axis-aligned ellipsoid (exact on the axes)."""
    q = (p - centre) / radii
    k0 = np.linalg.norm(q, axis=-1)
    k1 = np.linalg.norm(q / radii, axis=-1)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)


def _rotated_ellipsoid(p, centre, radii, axis):
    """Ellipsoid whose third semi-axis points along unit ``axis`` (others perpendicular)."""
    w = np.asarray(axis, float) / np.linalg.norm(axis)
    u = np.cross(w, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    d = p - centre
    local = np.stack([d @ u, d @ v, d @ w], axis=-1)
    return _ellipsoid(local, 0.0, radii)


def _cone_capsule(p, a, b, ra, rb):
    """Tapered capsule from a (radius ra) to b (radius rb); approximate for small tapers."""
    ba = b - a
    h = np.clip(((p - a) @ ba) / (ba @ ba), 0.0, 1.0)
    return np.linalg.norm(p - a - h[..., None] * ba, axis=-1) - (ra + (rb - ra) * h)


class FemurShape:
    """The implicit femur f(x) for a set of :class:`FemurParameters` (frame in module doc)."""

    def __init__(self, par: FemurParameters):
        self.par = par
        s = par.length_mm / 455.0
        self.s = s
        r_head = par.head_diameter_mm / 2
        self.head_centre = self._head_centre(par, r_head)
        self.r_head = r_head
        self.neck_base = np.array([0.0, 0.0, self.head_centre[2]
                                   - par.offset_mm / math.tan(math.radians(180 - par.neck_shaft_angle_deg))])
        self.z_bow = (60 * s, 395 * s)

    @staticmethod
    def _head_centre(par, r_head):
        """Head centre: ``offset_mm`` medial of the shaft axis, turned ``anteversion_deg`` forwards."""
        av = math.radians(par.anteversion_deg)
        return np.array([par.offset_mm * math.cos(av), par.offset_mm * math.sin(av), par.length_mm - r_head])

    def shaft_centre(self, z):
        """(x, y) of the shaft centreline at height z: a sine-shaped anterior bow [mm]."""
        z0, z1 = self.z_bow
        t = np.clip((z - z0) / (z1 - z0), 0.0, 1.0)
        return np.zeros_like(z), self.par.bow_mm * np.sin(np.pi * t)

    def shaft_radii(self, z):
        """Medial-lateral and anterior-posterior half-widths of the shaft at height z [mm]."""
        from scipy.interpolate import PchipInterpolator

        s, r = self.s, self.par.shaft_diameter_mm / 2
        zs = np.array([40, 70, 105, 150, 228, 300, 335, 360, 385, 410]) * s
        ml = np.array([2.45, 2.0, 1.35, 1.06, 1.0, 1.03, 1.12, 1.3, 1.55, 1.6]) * r
        ap = np.array([1.9, 1.55, 1.15, 1.0, 1.0, 1.02, 1.07, 1.12, 1.2, 1.2]) * r
        zc = np.clip(z, zs[0], zs[-1])
        return PchipInterpolator(zs, ml)(zc), PchipInterpolator(zs, ap)(zc)

    def __call__(self, p):
        """f(p) [mm]: negative inside the bone, approximately the signed distance."""
        s = self.s
        x, y, z = p[..., 0], p[..., 1], p[..., 2]
        xc, yc = self.shaft_centre(z)
        rx, ry = self.shaft_radii(z)
        # shaft: elliptical section, scaled to distance units by the smaller half-width
        rm = np.minimum(rx, ry)
        shaft = (np.hypot((x - xc) / rx, (y - yc) / ry) - 1.0) * rm
        shaft = _smax(shaft, np.maximum(30 * s - z, z - 415 * s), 10 * s)
        # linea aspera: a ridge along the posterior shaft
        ridge = np.hypot(x - xc, y - (yc - 0.9 * ry)) - 3.2 * s
        ridge = _smax(ridge, np.abs(z - 235 * s) - 105 * s, 25 * s)
        f = _smin(shaft, ridge, 4 * s)
        f = _smin(f, self._proximal(p), 9 * s)
        f = _smin(f, self._distal(p), 10 * s)
        return f

    def _proximal(self, p):
        s = self.s
        hc, nb = self.head_centre, self.neck_base
        head = np.linalg.norm(p - hc, axis=-1) - self.r_head
        axis = (hc - nb) / np.linalg.norm(hc - nb)
        neck_end = hc - 0.45 * self.r_head * axis
        neck = _cone_capsule(p, nb + 8 * s * axis, neck_end, 17.5 * s, 14.0 * s)
        f = _smin(head, neck, 6 * s)
        # greater trochanter: lateral, slightly posterior, top a little below the head
        gt = _rotated_ellipsoid(p, np.array([-22.0, -6.0, 402.0]) * s, np.array([14.0, 21.0, 30.0]) * s,
                                [-0.2, -0.1, 1.0])
        # intertrochanteric mass joining shaft, neck and trochanters
        it = _ellipsoid(p, np.array([-4.0, -3.0, 392.0]) * s, np.array([25.0, 17.0, 30.0]) * s)
        # lesser trochanter: posteromedial, below the neck
        lt = _rotated_ellipsoid(p, np.array([13.0, -13.0, 372.0]) * s, np.array([7.0, 7.0, 13.0]) * s,
                                [0.5, -0.6, 0.6])
        f = _smin(f, it, 12 * s)
        f = _smin(f, gt, 8 * s)
        return _smin(f, lt, 5 * s)

    def _distal(self, p):
        s = self.s
        # condyles: medial (+x) reaches the lowest point z = 0, lateral ~3 mm higher
        med = _rotated_ellipsoid(p, np.array([22.0, -6.0, 30.0]) * s, np.array([15.0, 30.0, 30.0]) * s,
                                 [0.0, 0.15, 1.0])
        lat = _rotated_ellipsoid(p, np.array([-22.0, -5.0, 33.0]) * s, np.array([16.5, 31.0, 30.0]) * s,
                                 [0.0, 0.1, 1.0])
        f = _smin(med, lat, 4 * s)
        # anterior block bearing the patellar surface, and the metaphysis above
        block = _ellipsoid(p, np.array([0.0, 5.0, 40.0]) * s, np.array([36.0, 23.0, 34.0]) * s)
        f = _smin(f, block, 8 * s)
        # intercondylar notch: a slot open distally and posteriorly, ending under the trochlea
        slot = np.hypot(p[..., 0], np.maximum(p[..., 2] - 20.0 * s, 0.0)) - 10.0 * s
        slot = _smax(slot, p[..., 1] + 3.0 * s, 6 * s)
        f = _smax(f, -slot, 3 * s)
        # trochlear groove on the anterior face
        groove = _cone_capsule(p, np.array([0.0, 37.0, 8.0]) * s, np.array([0.0, 34.0, 70.0]) * s,
                               9.0 * s, 7.0 * s)
        f = _smax(f, -groove, 4 * s)
        # epicondyles
        for sign in (1.0, -1.0):
            epi = np.linalg.norm(p - np.array([sign * 33.0, -4.0, 42.0]) * s, axis=-1) - 8.0 * s
            f = _smin(f, epi, 10 * s)
        return f

    def bounds(self):
        """A box [mm] enclosing the bone with a margin of a few voxels."""
        s, m = self.s, 4 * self.par.resolution_mm
        lo = np.array([-45 * s, -45 * s, 0.0]) - m
        hi = np.array([max(70 * s, self.head_centre[0] + self.r_head), 45 * s + self.par.bow_mm,
                       self.par.length_mm]) + m
        return lo, hi


def generate(par: FemurParameters = FemurParameters()):
    """The femur surface as a ``pyvista.PolyData`` of outward-oriented triangles [mm]."""
    import pyvista as pv

    shape = FemurShape(par)
    lo, hi = shape.bounds()
    h = par.resolution_mm
    dims = np.ceil((hi - lo) / h).astype(int) + 1
    grid = pv.ImageData(dimensions=dims, spacing=(h, h, h), origin=lo)
    values = np.empty(grid.n_points)
    nxy = dims[0] * dims[1]
    xs, ys = np.meshgrid(lo[0] + h * np.arange(dims[0]), lo[1] + h * np.arange(dims[1]), indexing="xy")
    for k in range(dims[2]):  # one z-slice at a time keeps memory small; x varies fastest
        p = np.stack([xs.ravel(), ys.ravel(), np.full(nxy, lo[2] + h * k)], axis=-1)
        values[k * nxy:(k + 1) * nxy] = shape(p)
    grid["f"] = np.round(values, 5)
    surf = grid.contour([0.0], scalars="f", method="flying_edges")
    surf = surf.connectivity("largest").extract_surface(algorithm=None).triangulate()
    surf = surf.smooth_taubin(n_iter=20, pass_band=0.05)
    surf = surf.decimate(1.0 - par.triangles / surf.n_cells, volume_preservation=True)
    surf = surf.clean().compute_normals(auto_orient_normals=True, consistent_normals=True, point_normals=False)
    surf.clear_data()
    return surf


def write_stl(path, surf, header: str = "") -> None:
    """Write triangles as binary STL (float32, facet normals from the vertex order), atomically."""
    from femstudy import atomic

    pts = np.asarray(surf.points, dtype=np.float64)
    tri = surf.regular_faces
    v = pts[tri]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    rec = np.zeros(len(tri), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = n, v
    head = header.encode("ascii", "replace")[:80].ljust(80, b" ")
    with atomic.atomic_path(path) as tmp:
        tmp.write_bytes(head + struct.pack("<I", len(tri)) + rec.tobytes())


def write_femur(path, parameters: FemurParameters = FemurParameters()):
    """Generate a femur from ``parameters`` and write it as binary STL; returns the surface.

    Parameters
    ----------
    path : path-like
        The STL to write (atomically; through a link, to its target).
    parameters : FemurParameters
        Length, head, neck, shaft … [mm, degrees]; the defaults give the built-in femur.

    Returns
    -------
    pyvista.PolyData

    Examples
    --------
    >>> surf = write_femur("small.stl", FemurParameters(length_mm=400, triangles=4000))  # doctest: +SKIP
    """
    surf = generate(parameters)
    write_stl(Path(path).resolve(), surf, header=f"femstudy built-in femur {parameters.digest()}")
    return surf
