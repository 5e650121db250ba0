"""Unit load patterns of the drill on the hole of one depth station.

Where the loads act (thesis §3.2.1 and docs/hole.md):

(a) cutting thrust — the lips cut the bottom of the hole: a traction along the drill axis d on
    the exposed drill-point cone with resultant 1 N·d. ``cone_traction = "allotta"`` (the
    default): a constant force per unit length of lip, as Allotta's model has it (Eq 2.18
    integrates a constant force per unit depth of the cone, and a lip's length grows with the
    depth), so the swept traction falls as 1/r, t = d / (r ∫ dA / r); ``"uniform"``: t = d / A
    (A the cone's area).
(b) cutting torque — tangential traction on the cone about the axis, moment 1 N·mm about d,
    no net force: "allotta", again a constant tangential force per unit lip length (Eq 2.19's
    moment per unit depth grows as r), t = θ̂ / (r A); "uniform", growing with the distance from
    the axis, t = k d × (x − c), k = 1 / ∫ |(x − c)⊥|² dA (c the cone's area centroid, on the
    axis for a whole cone).
(c) chip-evacuation torque — the chips rub the wall circumferentially (Eq 3.17, dT_c = R F_wf)
    with the chip pressure's growth along the engaged wall, dT_c/dζ ∝ exp(p ζ / D) (Eq 3.18's
    integrand; ζ the depth below the wall's top at that azimuth, p the growth exponent ηMD/S,
    D the drill diameter): t = k exp(p ζ / D) θ̂ on the wall, k = 1 / ∫ exp(p ζ / D) r dA,
    moment 1 N·mm about d (no net force when the engaged wall is axisymmetric).
(d) chip-evacuation thrust — ``on="bottom"`` (default): the chip column's axial pressure on
    the hole bottom, the same traction as (a); the axial force balance of the chip column
    (Eqs 3.1, 3.12) holds the chips between the pressure at the bottom and the friction on the
    drill's flute, and the wall friction F_wf is tangential, with no axial part, so the bone
    takes the evacuation thrust at the bottom. ``on="wall"``: axial wall friction over the
    engaged wall, t = exp(p ζ / D) d / ∫ exp(p ζ / D) dA, for comparison.

Nodal forces f_i = Σ_q w_q N_i(x_q) t(x_q) with a degree-6 rule on every facet and the P1/P2
trace shape functions of :mod:`femstudy.fe.loads`. The shape functions sum to 1 and
reproduce x on the (affine) facets, so Σ f_i = Σ_q w_q t_q and Σ x_i × f_i = Σ_q w_q x_q × t_q:
every normalisation above, made with the same quadrature sums, holds to round-off
(tests/test_hole_loads.py). A station without an exposed cone (drilled through) or without a
wall (the cone still entering) has zero patterns there and zero area. Units: N, N·mm, mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from skfem.quadrature import get_quadrature
from skfem.refdom import RefTri

from femstudy.errors import require
from femstudy.fe.loads import facet_node_indices, trace_shape_functions, outward_facet_normals
from femstudy.hole.dirichlet import facet_indices

#: Polynomial degree integrated exactly on each facet.
QUADRATURE_DEGREE = 6
EVACUATION_THRUST_PLACES = ("bottom", "wall")
CONE_TRACTIONS = ("allotta", "uniform")


@dataclass(frozen=True)
class FacetQuadrature:
    """Quadrature points on boundary facets of a system.

    facets : (f,) scikit-fem facet indices
    nodes  : (f, 3 or 6) facet node indices (vertices, then P2 mid-nodes)
    lam    : (q, 3) barycentric coordinates of the points on every facet
    x      : (f, q, 3) point coordinates [mm]
    w      : (f, q) weights [mm²]
    normal : (f, 3) outward unit normals
    """

    facets: np.ndarray
    nodes: np.ndarray
    lam: np.ndarray
    x: np.ndarray
    w: np.ndarray
    normal: np.ndarray
    order: int
    n_dofs: int

    @property
    def area_mm2(self) -> float:
        return float(self.w.sum())

    def shape(self) -> np.ndarray:
        """(q, 3 or 6) trace shape functions at the points."""
        return trace_shape_functions(self.order, self.lam)

    def forces(self, traction: np.ndarray) -> np.ndarray:
        """(n_dofs,) nodal forces [N] of a traction (f, q, 3) [MPa] at the points."""
        load = np.einsum("fq,qa,fqj->faj", self.w, self.shape(), traction)
        return np.bincount((3 * self.nodes[..., None] + np.arange(3)).ravel(), load.ravel(), minlength=self.n_dofs)

    def mean_operator(self) -> sp.csr_matrix:
        """(3, n_dofs): the area-weighted mean of the displacement over the facets."""
        weights = np.einsum("fq,qa->fa", self.w, self.shape()) / self.area_mm2
        cols = (3 * self.nodes[..., None] + np.arange(3)).reshape(-1)
        rows = np.tile(np.arange(3), self.nodes.size)
        return sp.csr_matrix((np.repeat(weights.ravel(), 3), (rows, cols)), shape=(3, self.n_dofs))


def facet_quadrature(system, faces: np.ndarray, degree: int = QUADRATURE_DEGREE) -> FacetQuadrature:
    """Quadrature on the facets ``faces`` ((k, 3) point indices of the assembled TetMesh).

    Parameters
    ----------
    system : :class:`femstudy.fe.FESystem`
    faces : (k, 3) point indices, e.g. ``station.faces["hole_wall"]``
    degree : polynomial degree the rule integrates exactly

    Returns
    -------
    :class:`FacetQuadrature`

    Examples
    --------
    >>> q = facet_quadrature(system, station.faces["hole_bottom"])  # doctest: +SKIP
    >>> f = q.forces(np.broadcast_to(-1.0 * q.normal[:, None], q.x.shape))  # 1 MPa pressure  # doctest: +SKIP
    """
    facets = facet_indices(system, faces) if len(faces) else np.empty(0, np.int64)
    X, W = get_quadrature(RefTri, degree)
    lam = np.column_stack([1 - X.sum(axis=0), X.T])
    mesh = system.mesh
    corners = mesh.p.T[mesh.facets[:, facets].T].reshape(len(facets), 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    x = np.einsum("qk,fkj->fqj", lam, corners)
    w = 2.0 * area[:, None] * W[None, :]
    normal = outward_facet_normals(mesh, facets) if len(facets) else np.empty((0, 3))
    nodes = facet_node_indices(system, facets) if len(facets) else np.empty((0, 3 * system.order), np.int64)
    return FacetQuadrature(facets, nodes, lam, x, w, normal, system.order, system.n_dofs)


@dataclass(frozen=True)
class HoleLoads:
    """Unit load patterns of one station (each an (n_dofs,) nodal force vector [N]).

    cutting_thrust    : 1 N along d on the exposed cone
    cutting_torque    : 1 N·mm about d on the cone, no net force
    evacuation_torque : 1 N·mm about d on the engaged wall, density ∝ exp(p ζ / D)
    evacuation_thrust : 1 N along d, on the cone or on the wall (``evacuation_thrust_on``)
    bottom_mean       : (3, n_dofs) sparse; ``bottom_mean @ u`` is the cone's mean displacement [mm]
    engaged_length_mm : depth of the wall's lowest point below its highest [mm]
    """

    cutting_thrust: np.ndarray
    cutting_torque: np.ndarray
    evacuation_torque: np.ndarray
    evacuation_thrust: np.ndarray
    bottom_mean: sp.csr_matrix
    axis: np.ndarray
    origin: np.ndarray
    bottom_centre: np.ndarray
    bottom_area_mm2: float
    wall_area_mm2: float
    engaged_length_mm: float
    growth_exponent: float
    evacuation_thrust_on: str

    NAMES = ("cutting_thrust", "cutting_torque", "evacuation_torque", "evacuation_thrust")

    @property
    def patterns(self) -> np.ndarray:
        """(n_dofs, 4), columns in :attr:`NAMES` order (amplitudes N, N·mm, N·mm, N)."""
        return np.column_stack([getattr(self, name) for name in self.NAMES])

    def force(self, cutting_thrust_N: float, cutting_torque_Nmm: float, evacuation_torque_Nmm: float = 0.0,
              evacuation_thrust_N: float = 0.0) -> np.ndarray:
        """Nodal forces [N] of the given load amplitudes."""
        return self.patterns @ np.array([cutting_thrust_N, cutting_torque_Nmm, evacuation_torque_Nmm,
                                         evacuation_thrust_N])


def _safe_inverse(value: float) -> float:
    return 1.0 / value if value > 0 else 0.0


def hole_loads(system, station, growth_exponent: float = 0.0, evacuation_thrust_on: str = "bottom",
               cone_traction: str = "allotta") -> HoleLoads:
    """The unit drill loads on the hole of ``station`` for a system assembled on ``station.mesh``.

    Parameters
    ----------
    system : :class:`femstudy.fe.FESystem` of ``station.mesh`` (P1 or P2)
    station : :class:`femstudy.hole.mesh.HoleStation`
    growth_exponent : p of the chip pressure exp(p ζ / D) along the engaged wall (0: uniform)
    evacuation_thrust_on : "bottom" (default) or "wall", where the evacuation thrust acts
    cone_traction : "allotta" (default) or "uniform", how the cutting loads spread over the cone

    Returns
    -------
    :class:`HoleLoads`

    Examples
    --------
    >>> loads = hole_loads(system, hole.at_station(3), growth_exponent=0.47)  # doctest: +SKIP
    >>> f = loads.force(cutting_thrust_N=20.0, cutting_torque_Nmm=15.0)  # doctest: +SKIP
    """
    require(evacuation_thrust_on in EVACUATION_THRUST_PLACES,
            f"the evacuation thrust acts on 'bottom' or 'wall', not '{evacuation_thrust_on}'")
    require(np.isfinite(growth_exponent), f"the growth exponent must be finite, got {growth_exponent}")
    require(cone_traction in CONE_TRACTIONS, f"the cone traction is 'allotta' or 'uniform', not '{cone_traction}'")
    hole = station.hole
    d, o = hole.frame.axis, hole.frame.origin
    diameter = 2 * hole.radius_mm

    cone = facet_quadrature(system, station.faces["hole_bottom"])
    area = cone.area_mm2
    centre = np.einsum("fq,fqj->j", cone.w, cone.x) / area if area > 0 else o + station.tip_depth_mm * d
    arm = cone.x - centre
    arm -= (arm @ d)[..., None] * d
    if cone_traction == "uniform":
        thrust = cone.forces(np.broadcast_to(d * _safe_inverse(area), cone.x.shape))
        k = _safe_inverse(np.einsum("fq,fqj,fqj->", cone.w, arm, arm))
        torque = cone.forces(k * np.cross(d, arm))
    else:  # constant force per unit lip length: tractions ∝ 1/r about the drill axis
        radial = cone.x - o
        radial -= (radial @ d)[..., None] * d
        r = np.linalg.norm(radial, axis=-1)
        inv_r = 1.0 / np.where(r > 0, r, np.inf)
        thrust = cone.forces(_safe_inverse(np.einsum("fq,fq->", cone.w, inv_r)) * inv_r[..., None] * d)
        tangent = np.cross(d, radial) * (inv_r ** 2)[..., None]  # θ̂ / r
        torque = cone.forces(_safe_inverse(area) * tangent)
    mean = cone.mean_operator() if area > 0 else sp.csr_matrix((3, system.n_dofs))

    wall = facet_quadrature(system, station.faces["hole_wall"])
    top_at_vertices = hole.point_top_depth[_wall_points(system, wall)]
    zeta = (wall.x - o) @ d - np.einsum("qk,fk->fq", wall.lam, top_at_vertices)
    density = np.exp(growth_exponent * zeta / diameter)
    radial = wall.x - o
    radial -= (radial @ d)[..., None] * d
    r = np.linalg.norm(radial, axis=-1)
    tangent = np.cross(d, radial) / np.where(r > 0, r, 1.0)[..., None]
    k_wall = _safe_inverse(np.einsum("fq,fq,fq->", wall.w, density, r))
    evacuation_torque = wall.forces(k_wall * density[..., None] * tangent)
    if evacuation_thrust_on == "bottom":
        evacuation_thrust = thrust
    else:
        evacuation_thrust = wall.forces(_safe_inverse(np.einsum("fq,fq->", wall.w, density))
                                        * density[..., None] * d)
    wall_vertices = system.mesh.p.T[system.mesh.facets[:, wall.facets].ravel()]
    engaged = float(((wall_vertices - o) @ d).max() - hole.hole_top_mm) if wall.area_mm2 > 0 else 0.0
    return HoleLoads(thrust, torque, evacuation_torque, evacuation_thrust, mean, d, o, centre, area,
                     wall.area_mm2, engaged, float(growth_exponent), evacuation_thrust_on)


def _wall_points(system, quadrature: FacetQuadrature) -> np.ndarray:
    """(f, 3) TetMesh point indices of the facets' vertices, in the quadrature's vertex order."""
    vertex_to_point = np.full(system.mesh.nvertices, -1, dtype=np.int64)
    used = np.flatnonzero(system.point_index >= 0)
    vertex_to_point[system.point_index[used]] = used
    return vertex_to_point[system.mesh.facets[:, quadrature.facets].T].reshape(len(quadrature.facets), 3)
