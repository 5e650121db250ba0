"""A scikit-fem stand-in for femstudy's FE solver, used to prove the peer plumbing.

It has the planned interface of ``femstudy.fe`` — ``assemble``, ``drill_patch``, ``clamp``,
``solve_static``, ``solve_transient`` with the same arguments and meanings — and is written
the plain way: P2 vector elasticity from :mod:`skfem.models.elasticity` assembled per region,
a thrust/torque patch over the boundary facets near the drill entry point, PARDISO (or SuperLU
with a symmetric minimum-degree ordering) and Newmark average acceleration. It also builds the
test geometry: a clamped hollow tube with a cortical mid-shaft and cancellous ends.

Units: mm, N, N·mm, MPa, tonne/mm³, s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import (Basis, BilinearForm, ElementTetP2, ElementVector, FacetBasis, Functional, LinearForm,
                   MeshTet)
from skfem.helpers import dot
from skfem.models.elasticity import lame_parameters, linear_elasticity

from femstudy.materials import BoneMaterials
from femstudy.export.p2 import p2_layout
from femstudy.femur_mesh import (CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL, Clamps, DrillSite,
                                  TetMesh)


def tube_model(length_mm: float = 200.0, outer_radius_mm: float = 14.0, inner_radius_mm: float = 6.5,
               n_radial: int = 2, n_around: int = 16, n_along: int = 20,
               cancellous_length_mm: float = 40.0) -> tuple[TetMesh, Clamps, DrillSite]:
    """A hollow circular tube along z, meshed as a structured (r, θ, z) grid of hexahedra each
    split into 6 tetrahedra (conforming: every hex uses the same split in index space).

    Elements whose centroid lies within ``cancellous_length_mm`` of an end are cancellous
    (proximal at z = 0, distal at z = L), the rest cortical. The end faces are clamped; the
    drill enters at mid-length on the outer surface at +x, drilling along −x.
    """
    r = np.linspace(inner_radius_mm, outer_radius_mm, n_radial + 1)
    theta = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    z = np.linspace(0, length_mm, n_along + 1)
    R, T, Z = np.meshgrid(r, theta, z, indexing="ij")
    points = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(), Z.ravel()])

    def index(i, j, k):
        return (i * n_around + j % n_around) * (n_along + 1) + k

    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(n_radial), np.arange(n_around),
                                              np.arange(n_along), indexing="ij"))
    corner = {(a, b, c): index(i + a, j + b, k + c) for a in (0, 1) for b in (0, 1) for c in (0, 1)}
    tets = []
    for order in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        step = [0, 0, 0]
        path = [corner[tuple(step)]]
        for axis in order:                       # Kuhn split: walk 000 -> 111 one axis at a time
            step[axis] = 1
            path.append(corner[tuple(step)])
        tets.append(np.column_stack(path))
    tets = np.concatenate(tets)
    x = points[tets]
    det = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
    tets[det < 0] = tets[det < 0][:, [0, 2, 1, 3]]
    zc = points[tets, 2].mean(axis=1)
    region = np.full(len(tets), CORTICAL, dtype=np.int8)
    region[zc < cancellous_length_mm] = CANCELLOUS_PROXIMAL
    region[zc > length_mm - cancellous_length_mm] = CANCELLOUS_DISTAL
    mesh = TetMesh(points=points, tets=tets.astype(np.int64), region=region)
    clamps = Clamps(proximal=np.isclose(points[:, 2], 0.0), distal=np.isclose(points[:, 2], length_mm))
    site = DrillSite(name="tube mid-length", entry_point=np.array([outer_radius_mm, 0.0, length_mm / 2]),
                     outward_normal=np.array([1.0, 0.0, 0.0]), direction=np.array([-1.0, 0.0, 0.0]),
                     cortical_thickness_mm=outer_radius_mm - inner_radius_mm)
    return mesh, clamps, site


@dataclass
class System:
    """Assembled P2 model: stiffness K [N/mm] and consistent mass M [tonne] on ``basis``;
    ``nodes`` (n, 3) [mm] and ``cells`` (m, 10) in scikit-fem's P2 layout, node i ↔ DOFs 3i..3i+2."""

    basis: Basis
    nodes: np.ndarray
    cells: np.ndarray
    region: np.ndarray
    K: sp.csr_matrix
    M: sp.csr_matrix

    order = 2

    @property
    def mesh(self) -> MeshTet:
        return self.basis.mesh

    @property
    def n_dofs(self) -> int:
        return self.basis.N


@dataclass
class Patch:
    """Unit drill loads as DOF vectors: thrust (resultant 1 N along the drill direction) and
    torque (1 N·mm about the drill axis, zero net force)."""

    thrust: np.ndarray
    torque: np.ndarray

    @property
    def patterns(self) -> np.ndarray:
        """(n_dofs, 2): thrust and torque columns, paired with amplitudes (thrust_N, torque_Nmm)."""
        return np.column_stack([self.thrust, self.torque])


@dataclass
class Constraints:
    """Fixed DOFs (every DOF of the clamped P2 nodes) and the remaining free ones."""

    fixed: np.ndarray
    free: np.ndarray

    def expand(self, u_free: np.ndarray) -> np.ndarray:
        u = np.zeros(len(self.fixed) + len(self.free))
        u[self.free] = u_free
        return u


@dataclass
class Factorized:
    """The clamped model: K and M restricted to the free DOFs, and the solver of K_ff."""

    system: "System"
    bc: Constraints
    solve: Callable[[np.ndarray], np.ndarray]


@dataclass
class TransientResult:
    """The march's times; the fields go to the observer."""

    time_s: np.ndarray
    scheme: str = "stepping"
    n_vectors: int = 0


def region_materials(materials: BoneMaterials) -> dict:
    """Region code -> material: cortical for region 1, cancellous for the two others."""
    return {CORTICAL: materials.cortical, CANCELLOUS_PROXIMAL: materials.cancellous,
            CANCELLOUS_DISTAL: materials.cancellous}


def assemble(mesh: TetMesh, materials: BoneMaterials, order: int = 2, mass_intorder: int | None = None
             ) -> System:
    """K = Σ_regions ∫ ε(v) : C_r ε(u) dV and M = Σ_regions ∫ ρ_r v·u dV.

    ``mass_intorder`` sets the quadrature degree of the mass form: None integrates it exactly
    (degree 4 for P2); 2 is the 4-point rule CalculiX's C3D10 uses.
    """
    if order != 2:
        raise ValueError("the stand-in assembles P2 only")
    skmesh = MeshTet(np.ascontiguousarray(mesh.points.T), np.ascontiguousarray(mesh.tets.T))
    element = ElementVector(ElementTetP2())
    basis = Basis(skmesh, element)
    K = sp.csr_matrix((basis.N, basis.N))
    M = sp.csr_matrix((basis.N, basis.N))
    for code, spec in region_materials(materials).items():
        cells = np.flatnonzero(mesh.region == code)
        if len(cells) == 0:
            continue
        part = basis.with_elements(cells)
        K = K + linear_elasticity(*lame_parameters(spec.E_MPa, spec.nu)).assemble(part)
        mass_basis = part if mass_intorder is None else Basis(skmesh, element, elements=cells,
                                                              intorder=mass_intorder)
        M = M + _mass(spec.density_t_mm3).assemble(mass_basis)
    nodes, cells = p2_layout(basis)
    return System(basis, nodes, cells, np.asarray(mesh.region), K.tocsr(), M.tocsr())


def _mass(rho: float) -> BilinearForm:
    @BilinearForm
    def mass(u, v, w):
        return rho * dot(u, v)
    return mass


def drill_patch(system: System, site: DrillSite, radius_mm: float = 1.35) -> Patch:
    """Thrust and torque as tractions over the boundary facets whose centroid lies within
    ``radius_mm`` of the entry point on the side the outward normal faces.

    thrust: uniform pressure p = 1 / A along the drill direction d (resultant 1 N);
    torque: τ(x) = d × r(x) / J, r = in-plane offset from the patch centroid, J = ∫ |r|² dA
    (net force 0, moment 1 N·mm about d).
    """
    mesh = system.basis.mesh
    facets = mesh.boundary_facets()
    centroid = mesh.p[:, mesh.facets[:, facets]].mean(axis=1).T
    near = np.linalg.norm(centroid - site.entry_point, axis=1) <= radius_mm
    outward = (centroid - site.entry_point) @ site.outward_normal > -0.25 * radius_mm
    chosen = facets[near & outward]
    if len(chosen) == 0:
        raise ValueError("no boundary facet within the patch radius of the entry point")
    fb = FacetBasis(mesh, system.basis.elem, facets=chosen)
    d = np.asarray(site.direction, float)[:, None, None]
    area = Functional(lambda w: 1.0 + 0 * w.x[0]).assemble(fb)
    c = np.array([Functional(lambda w, i=i: w.x[i]).assemble(fb) for i in range(3)]) / area

    def offset(x):
        rel = x - c[:, None, None]
        return rel - (d * rel).sum(axis=0) * d

    J = Functional(lambda w: (offset(w.x) ** 2).sum(axis=0)).assemble(fb)
    thrust = LinearForm(lambda v, w: dot(v, d) / area).assemble(fb)
    torque = LinearForm(lambda v, w: dot(v, np.cross(d, offset(w.x), axis=0)) / J).assemble(fb)
    return Patch(thrust=thrust, torque=torque)


def clamp(system: System, clamps: Clamps) -> Constraints:
    """Fix every DOF on boundary facets whose three vertices are all clamped (P2 mid-edge
    nodes included)."""
    mesh = system.basis.mesh
    facets = mesh.boundary_facets()
    held = facets[clamps.any[mesh.facets[:, facets]].all(axis=0)]
    fixed = system.basis.get_dofs(facets=held).flatten()
    if len(fixed) == 0:
        raise ValueError("the clamps select no DOFs")
    free = np.setdiff1d(np.arange(system.basis.N), fixed)
    return Constraints(fixed=np.sort(fixed), free=free)


def _factorise(A: sp.spmatrix) -> Callable[[np.ndarray], np.ndarray]:
    """A solver for A x = b, factorised once: PARDISO if present, else SuperLU (MMD on AᵀA+A)."""
    try:
        import pypardiso
        solver = pypardiso.PyPardisoSolver()
        A = sp.csr_matrix(A)
        solver.factorize(A)
        return lambda b: solver.solve(A, b)
    except ImportError:
        lu = spla.splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A",
                       options={"SymmetricMode": True}, diag_pivot_thresh=0.0)
        return lu.solve


def factorize(system: System, bc: Constraints) -> Factorized:
    """K_ff factorised once."""
    return Factorized(system, bc, _factorise(system.K[bc.free][:, bc.free]))


def solve_static(fs: Factorized, force: np.ndarray) -> np.ndarray:
    """u with K u = f on the free DOFs and u = 0 on the fixed ones [mm]."""
    return fs.bc.expand(fs.solve(force[fs.bc.free]))


def solve_transient(fs: Factorized, patterns: np.ndarray, amplitudes: np.ndarray, times_s: np.ndarray, *,
                    observer=None) -> TransientResult:
    """Newmark average acceleration (β = 1/4, γ = 1/2), undamped, fixed Δt = times_s[1] − times_s[0].

    M a + K u = f(t_n) = patterns @ amplitudes[n]; from rest, with M a_0 = f(t_0).
    K_eff = K + 4/Δt² M is factorised once;  u_{n+1} = K_eff⁻¹ [f_{n+1} + M(4/Δt² u_n + 4/Δt v_n + a_n)],
    a_{n+1} = 4/Δt² (u_{n+1} − u_n) − 4/Δt v_n − a_n,  v_{n+1} = v_n + Δt/2 (a_n + a_{n+1}).
    ``observer.step(n, u)`` receives every step's full field.
    """
    t = np.asarray(times_s, dtype=float)
    dt = float(t[1] - t[0])
    system, bc = fs.system, fs.bc
    free = bc.free
    K, M = system.K[free][:, free], system.M[free][:, free]
    P = np.asarray(patterns)[free]
    u, v = np.zeros(len(free)), np.zeros(len(free))
    a = _factorise(M)(P @ amplitudes[0]) if np.any(amplitudes[0]) else np.zeros(len(free))
    keff = _factorise(K + (4 / dt**2) * M)
    if observer is not None:
        observer.step(0, bc.expand(u))
    for n in range(1, len(t)):
        u_new = keff(P @ amplitudes[n] + M @ ((4 / dt**2) * u + (4 / dt) * v + a))
        a_new = (4 / dt**2) * (u_new - u) - (4 / dt) * v - a
        v = v + dt / 2 * (a + a_new)
        u, a = u_new, a_new
        if observer is not None:
            observer.step(n, bc.expand(u))
    return TransientResult(t)
