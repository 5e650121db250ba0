"""Stress measures of a solved station: at stated distances from the hole, and outside an
exclusion zone around it.

* **At distance δ** (:func:`distance_measures`): over the points at δ from the hole surface
  (:func:`femstudy.hole.samples.offset_samples`, every azimuth and depth; kind "distance"), and
  over those of them beside the cylindrical wall (r = R + δ down to the corner depth; kind
  "wall"), the largest von
  Mises stress and where it is, the largest and smallest principal stresses and strains, and
  the smallest strength ratio (:mod:`femstudy.failure`: Tsai–Wu for cortical bone about the
  long axis, von Mises against the mean strength for cancellous bone). Points outside the
  bone (above the top, in the canal) are skipped; where the curve leaves the bone, the point
  on the bone's surface is added (:meth:`~femstudy.hole.samples.OffsetSamples.with_boundary_points`),
  so that a maximum on the canal under the tip or on the entry surface is taken on that
  surface at every refinement; where it passes from cortical into cancellous bone, a point on
  either side of that interface is added, each in an element of its own side, so the stress
  that jumps there is read on both sides of it.
* **Outside an exclusion radius ρ** (:func:`exclusion_measures`): the same over the
  stiffness quadrature points of the station farther than ρ from the hole surface, excluding
  points within ``cut_margin_mm`` of a cut-face node (there the local solution is the
  interpolated global data) and points within the clamped length of either end of the femur.

Stresses are the elements' own P2 fields at the points (σ = D ε(u)), strains ε = D⁻¹σ
(tensor strains for the principal values). Units: mm, MPa, strain [-].
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from femstudy.failure import cancellous_strength_ratio, cortical_strength_ratio, strain_ratio
from femstudy.fe.post import quadrature_points, stress_projection, von_mises
from femstudy.femur_mesh import CORTICAL
from femstudy.hole.samples import hole_distance, offset_samples

log = logging.getLogger(__name__)

#: Measure kinds: at a distance from the hole surface (wall, corner, cone and tip), at a
#: distance from its cylindrical wall only (r = R + δ over the engaged depth), or the maximum
#: outside an exclusion radius.
KINDS = ("distance", "wall", "exclusion")


@dataclass(frozen=True)
class HoleMeasure:
    """Stress measures of one loading over one point set of one station.

    loading : "dynamic" or "static"; station : station number; tip_depth_mm : its drill-tip depth
    kind : "distance" (points at ``radius_mm`` from the hole surface), "wall" (those of them
           beside the cylindrical wall) or "exclusion" (farther than it)
    von_mises_MPa, location_mm : the largest von Mises stress and its point (global frame)
    location_distance_mm : that point's distance from the hole surface
    max_principal_stress_MPa, min_principal_stress_MPa : extreme principal stresses
    max_principal_strain, min_principal_strain : extreme principal strains [-]
    strength_ratio : smallest load factor to failure by the stress criteria (femstudy.failure:
           Tsai–Wu for cortical, von Mises for cancellous bone) over the set
    strain_ratio : smallest load factor to the cortical maximum principal strain criterion
           (femstudy.failure.strain_ratio) over the set's cortical points (inf without any)
    points : how many points of the set lie in bone
    """

    loading: str
    station: int
    tip_depth_mm: float
    kind: str
    radius_mm: float
    von_mises_MPa: float
    location_mm: tuple
    location_distance_mm: float
    max_principal_stress_MPa: float
    min_principal_stress_MPa: float
    max_principal_strain: float
    min_principal_strain: float
    strength_ratio: float
    strain_ratio: float
    points: int

    def row(self) -> dict:
        """A flat dict, units in the keys."""
        out = {k: v for k, v in self.__dict__.items() if k != "location_mm"}
        out.update({f"location_{a}_mm": float(x) for a, x in zip("xyz", self.location_mm)})
        return out


def _tensor(voigt: np.ndarray, shear_factor: float) -> np.ndarray:
    s = np.asarray(voigt, float)
    t = np.empty(s.shape[:-1] + (3, 3))
    t[..., 0, 0], t[..., 1, 1], t[..., 2, 2] = s[..., 0], s[..., 1], s[..., 2]
    t[..., 1, 2] = t[..., 2, 1] = shear_factor * s[..., 3]
    t[..., 0, 2] = t[..., 2, 0] = shear_factor * s[..., 4]
    t[..., 0, 1] = t[..., 1, 0] = shear_factor * s[..., 5]
    return t


@dataclass(frozen=True)
class _PointValues:
    """Measured points (n, 3) [mm], their distance from the hole [mm] (n,), and per point and
    loading (n, k): von Mises [MPa], extreme principal stresses [MPa] and strains, and the
    strength and strain ratios (femstudy.failure)."""

    points: np.ndarray
    distance: np.ndarray
    von_mises: np.ndarray
    stress_max: np.ndarray
    stress_min: np.ndarray
    strain_max: np.ndarray
    strain_min: np.ndarray
    strength_ratio: np.ndarray
    strain_ratio: np.ndarray

    def subset(self, chosen: np.ndarray) -> _PointValues:
        return _PointValues(*(getattr(self, f.name)[chosen] for f in fields(self)))


def _point_values(points, distance, stress, D, region, long_axis) -> _PointValues:
    """The measured quantities of stresses (n, k, 6) at points (n, 3) with element stiffnesses D (n, 6, 6)."""
    strain = np.linalg.solve(D[:, None], stress[..., None])[..., 0]  # ε = D⁻¹σ, engineering shear
    principal_stress = np.linalg.eigvalsh(_tensor(stress, 1.0))
    principal_strain = np.linalg.eigvalsh(_tensor(strain, 0.5))
    vm = von_mises(stress)  # (n, k)
    cortical = region == CORTICAL
    ratio = np.where(cortical[:, None], cortical_strength_ratio(stress, long_axis), cancellous_strength_ratio(vm))
    strained = np.where(cortical[:, None], strain_ratio(principal_strain[..., -1], principal_strain[..., 0]), np.inf)
    return _PointValues(points, distance, vm, principal_stress[..., -1], principal_stress[..., 0],
                        principal_strain[..., -1], principal_strain[..., 0], ratio, strained)


def _measures(values: _PointValues, context: dict, loadings) -> list[HoleMeasure]:
    """Per loading, the extremes of ``values`` over its points and where von Mises peaks."""
    points, distance = values.points, values.distance
    if len(points) == 0:
        return [HoleMeasure(name, **context, von_mises_MPa=np.nan, location_mm=(np.nan,) * 3,
                            location_distance_mm=np.nan, max_principal_stress_MPa=np.nan,
                            min_principal_stress_MPa=np.nan, max_principal_strain=np.nan,
                            min_principal_strain=np.nan, strength_ratio=np.nan, strain_ratio=np.nan, points=0)
                for name in loadings]
    vm = values.von_mises
    out = []
    for j, name in enumerate(loadings):
        at = int(np.argmax(vm[:, j]))
        out.append(HoleMeasure(name, **context, von_mises_MPa=float(vm[at, j]), location_mm=tuple(map(float, points[at])),
                               location_distance_mm=float(distance[at]),
                               max_principal_stress_MPa=float(values.stress_max[:, j].max()),
                               min_principal_stress_MPa=float(values.stress_min[:, j].min()),
                               max_principal_strain=float(values.strain_max[:, j].max()),
                               min_principal_strain=float(values.strain_min[:, j].min()),
                               strength_ratio=float(values.strength_ratio[:, j].min()),
                               strain_ratio=float(values.strain_ratio[:, j].min()), points=len(points)))
    return out


@dataclass(frozen=True)
class DistanceSamples:
    """The points at one distance δ [mm] from the hole that lie in the bone of a station's local
    mesh, located once (their elements depend only on the mesh): points (n, 3) [mm], element
    (n,), and ``wall`` (n,) True beside the cylindrical wall."""

    distance_mm: float
    points: np.ndarray
    element: np.ndarray
    wall: np.ndarray


def distance_samples(system, station, distances_mm, keep: Path | None = None) -> tuple[DistanceSamples, ...]:
    """The sample points at each distance δ from the hole (module docstring), with the points
    where the curve leaves the bone or crosses a material interface, located in ``system``'s
    mesh; any solution on that mesh (other materials, other loads) is measured on them.

    They depend on geometry alone: with a ``keep`` folder they are stored there under the
    SHA-256 of the mesh, its regions, the station's hole and frame, the distances and the source
    of the code that finds them (:func:`samples_fingerprint`), so a repeated study locates none.
    """
    from femstudy.fe.kept import read_store, write_store
    from femstudy.hole.probe import MeshLocator

    path = None if keep is None else Path(keep) / f"samples-{samples_fingerprint(system, station, distances_mm)}.npz"
    names = [f"{part}_{i}" for i in range(len(distances_mm)) for part in ("points", "element", "wall")]
    stored = None if path is None else read_store(path, names, "sample points")
    if stored is not None:
        kept = tuple(DistanceSamples(float(d), stored[f"points_{i}"], stored[f"element_{i}"], stored[f"wall_{i}"])
                     for i, d in enumerate(distances_mm))
        if all(_placed(system, station, found) for found in kept):
            return kept
        log.warning("ignoring kept sample points %s: they fail the check against this mesh and hole", path)
    locator = MeshLocator(system)
    out = []
    for delta in distances_mm:
        samples = offset_samples(station, delta).with_boundary_points(locator.label)
        element = locator.locate(samples.points)[0]
        inside = element >= 0
        out.append(DistanceSamples(float(delta), samples.points[inside], element[inside], samples.of("wall")[inside]))
    if path is not None:
        write_store(path, "sample points", **{f"{part}_{i}": getattr(found, part) for i, found in enumerate(out)
                                              for part in ("points", "element", "wall")})
    return tuple(out)


def _placed(system, station, found: DistanceSamples) -> bool:
    """Kept sample points are what :func:`distance_samples` would give: each at its distance
    from the hole and inside its element (to round-off)."""
    from femstudy.hole.probe import BOUNDARY_TOLERANCE, reference_coordinates

    n = len(found.points)
    if found.points.shape != (n, 3) or found.element.shape != (n,) or found.wall.shape != (n,) \
            or found.wall.dtype != bool or not np.issubdtype(found.element.dtype, np.integer):
        return False
    if n == 0:
        return True
    if found.element.min() < 0 or found.element.max() >= system.n_tets:
        return False
    at_distance = np.abs(hole_distance(station, found.points) - found.distance_mm) <= 1e-9 * (1 + found.distance_mm)
    inside = reference_coordinates(system, found.element, found.points)[2] >= -BOUNDARY_TOLERANCE
    return bool(at_distance.all() and inside.all())


@functools.cache
def _locating_code() -> bytes:
    """The source of the code that places and locates the sample points (read once a process)."""
    import inspect

    from femstudy.hole import probe, samples

    return "".join(inspect.getsource(x) for x in (samples, probe, distance_samples)).encode()


def samples_fingerprint(system, station, distances_mm) -> str:
    """SHA-256 (32 hex digits) of what :func:`distance_samples` reads: the mesh's points,
    tetrahedra and regions, the station's hole (radius, point angle, top, corner and tip depths)
    and frame, the distances, and the source of the modules that place and locate the points."""
    import hashlib

    hole = station.hole
    digest = hashlib.sha256(_locating_code())
    scalars = [hole.radius_mm, hole.point_angle_deg, hole.hole_top_mm, station.corner_depth_mm, station.tip_depth_mm]
    for array in (system.mesh.p, system.mesh.t, system.region, np.array(scalars, float), hole.frame.origin,
                  hole.frame.axis, hole.frame.e1, hole.frame.e2, np.asarray(distances_mm, float)):
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype.str}{array.shape}".encode())
        digest.update(array.data)
    return digest.hexdigest()[:32]


def distance_measures(system, station, u: np.ndarray, distances_mm, long_axis, loadings=("dynamic",),
                      samples: tuple[DistanceSamples, ...] | None = None) -> list[HoleMeasure]:
    """Measures over the points at each distance δ from the hole (module docstring).

    Parameters
    ----------
    system : :class:`femstudy.fe.FESystem` assembled on ``station.mesh``
    station : :class:`femstudy.hole.mesh.HoleStation`
    u : (n_dofs, k) displacements [mm], one column per loading
    distances_mm : distances δ from the hole surface [mm]
    long_axis : (3,) the bone's long axis (cortical strength frame)
    loadings : k names of the columns of ``u``
    samples : the points of :func:`distance_samples` on this mesh, when already located

    Returns
    -------
    list of :class:`HoleMeasure`, loadings fastest

    Examples
    --------
    >>> distance_measures(system, station, u, (0.5, 1.0), model.frame.up)  # doctest: +SKIP
    """
    from femstudy.hole.probe import point_probe

    u = np.asarray(u, float).reshape(system.n_dofs, -1)
    located = {s.distance_mm: s for s in (distance_samples(system, station, distances_mm) if samples is None
                                          else samples)}
    out = []
    for delta in distances_mm:
        found = located[float(delta)]
        e = found.element
        probe = point_probe(system, found.points, e)
        values = _point_values(found.points, np.full(len(e), float(delta)), probe.stress(u),
                               system.materials.D[system.materials.index[e]], system.region[e], long_axis)
        for kind, chosen in (("distance", np.ones(len(e), bool)), ("wall", found.wall)):
            context = {"station": station.index, "tip_depth_mm": station.tip_depth_mm, "kind": kind,
                       "radius_mm": float(delta)}
            out += _measures(values.subset(chosen), context, loadings)
    return out


def exclusion_measures(system, station, u: np.ndarray, radii_mm, long_axis, excluded: np.ndarray,
                       loadings=("dynamic",)) -> list[HoleMeasure]:
    """Measures over the quadrature points farther than each radius ρ from the hole.

    Parameters
    ----------
    system, station, u, long_axis, loadings : as :func:`distance_measures`
    radii_mm : exclusion radii ρ [mm]
    excluded : (n_tets, nq) True at quadrature points never counted (near the cut faces, in a clamp zone)

    Returns
    -------
    list of :class:`HoleMeasure`, loadings fastest

    Examples
    --------
    >>> exclusion_measures(system, station, u, (1.0, 2.0), axis, np.zeros((system.n_tets, 4), bool))  # doctest: +SKIP
    """
    u = np.asarray(u, float).reshape(system.n_dofs, -1)
    nq = len(system.ref.weights)
    points = quadrature_points(system).reshape(-1, 3)
    stress = stress_projection(system, u).reshape(len(points), 6, -1).transpose(0, 2, 1)  # (n, k, 6)
    distance = hole_distance(station, points)
    element = np.repeat(np.arange(system.n_tets), nq)
    counted = (distance > min(radii_mm, default=np.inf)) & ~np.asarray(excluded).ravel()
    e = element[counted]
    values = _point_values(points[counted], distance[counted], stress[counted],
                           system.materials.D[system.materials.index[e]], system.region[e], long_axis)
    out = []
    for rho in radii_mm:
        context = {"station": station.index, "tip_depth_mm": station.tip_depth_mm, "kind": "exclusion",
                   "radius_mm": float(rho)}
        out += _measures(values.subset(values.distance > rho), context, loadings)
    return out
