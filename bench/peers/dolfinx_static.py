"""Static solve of a peer case (bench/peers/case.py) with DOLFINx 0.5: P2 vector Lagrange.

    /usr/bin/python3 bench/peers/dolfinx_static.py CASE.npz OUT.npz --solver mumps|gamg

Runs with the system Python (Debian's python3-dolfinx, PETSc 3.18), serially. It rebuilds the
linear tetrahedral mesh from the P2 elements' vertices, assigns E and ν per region through
piecewise-constant Lamé fields, and solves

    ∫ σ(u) : ε(v) dV = v · f,   σ = 2μ ε + λ tr(ε) I,   u = 0 on the fixed nodes,

with femstudy's assembled load vector f. femstudy's P2 nodes are matched to DOLFINx's DOF
coordinates with a k-d tree (every node must find a distinct DOF within 1e-9 of the mesh
size), so loads go in and displacements come out in femstudy's order.

Solvers: ``mumps`` — Cholesky (LDLᵀ) factorisation with MUMPS; ``gamg`` — conjugate gradients
preconditioned by PETSc's smoothed-aggregation algebraic multigrid with the six rigid-body
modes as near-null space, relative residual 1e-10.

Writes OUT.npz: ``u`` (3n,) [mm] in femstudy's DOF order, ``iterations``, and phase times
[s] ``t_read``, ``t_setup`` (mesh, spaces, node matching), ``t_assemble``,
``t_factor`` (factorisation or preconditioner set-up), ``t_solve``.
"""

import argparse
import time

import numpy as np
import ufl
from dolfinx import fem, la
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

SOLVER_OPTIONS = {
    "mumps": {"ksp_type": "preonly", "pc_type": "cholesky", "pc_factor_mat_solver_type": "mumps"},
    "gamg": {"ksp_type": "cg", "ksp_rtol": 1e-10, "ksp_max_it": 2000, "pc_type": "gamg",
             "pc_gamg_type": "agg", "pc_gamg_coarse_eq_limit": 1000, "mg_levels_ksp_type": "chebyshev",
             "mg_levels_pc_type": "jacobi", "mg_levels_esteig_ksp_type": "cg"},
}


def linear_mesh(nodes, elements):
    """DOLFINx mesh of the P2 elements' vertex tetrahedra, and region of each local cell."""
    vertex_ids, cells = np.unique(elements[:, :4], return_inverse=True)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", "tetrahedron", 1))
    msh = dmesh.create_mesh(MPI.COMM_SELF, cells.reshape(-1, 4).astype(np.int64),
                            np.ascontiguousarray(nodes[vertex_ids]), domain)
    return msh, np.asarray(msh.topology.original_cell_index)


def cellwise(msh, original, per_element):
    """A DG0 function with value ``per_element[original cell]`` on each cell."""
    f = fem.Function(fem.FunctionSpace(msh, ("DG", 0)))
    f.x.array[f.function_space.dofmap.list.array] = per_element[original]
    return f


def match_nodes(V, nodes):
    """DOLFINx block (node) index of each femstudy P2 node, by coordinates."""
    coords = V.tabulate_dof_coordinates()
    distance, block = cKDTree(coords).query(nodes)
    size = np.ptp(nodes, axis=0).max()
    if distance.max() > 1e-9 * size or len(np.unique(block)) != len(nodes) or len(coords) != len(nodes):
        raise SystemExit(f"node matching failed: {len(nodes)} femstudy nodes, {len(coords)} DOFs, "
                         f"largest distance {distance.max():.3g} mm")
    return block


def rigid_body_modes(V):
    """Orthonormalised translations and infinitesimal rotations as PETSc vectors."""
    x = V.tabulate_dof_coordinates()
    modes = [la.create_petsc_vector(V.dofmap.index_map, 3) for _ in range(6)]
    arrays = [np.zeros((len(x), 3)) for _ in range(6)]
    for c in range(3):
        arrays[c][:, c] = 1.0
    arrays[3][:, 0], arrays[3][:, 1] = -x[:, 1], x[:, 0]
    arrays[4][:, 0], arrays[4][:, 2] = x[:, 2], -x[:, 0]
    arrays[5][:, 2], arrays[5][:, 1] = x[:, 1], -x[:, 2]
    for vec, arr in zip(modes, arrays):
        vec.array[:] = arr.ravel()
    la.orthonormalize(modes)
    return PETSc.NullSpace().create(vectors=modes)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case")
    parser.add_argument("out")
    parser.add_argument("--solver", choices=sorted(SOLVER_OPTIONS), default="mumps")
    args = parser.parse_args()
    times = {}
    t0 = time.perf_counter()
    data = np.load(args.case)
    nodes, elements, region = data["nodes"], data["elements"], data["region"]
    codes = data["material_codes"]
    E, nu = np.zeros(codes.max() + 1), np.zeros(codes.max() + 1)
    E[codes], nu[codes] = data["youngs_modulus_MPa"], data["poissons_ratio"]
    E, nu = E[region], nu[region]
    times["t_read"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    msh, original = linear_mesh(nodes, elements)
    lam = cellwise(msh, original, E * nu / ((1 + nu) * (1 - 2 * nu)))
    mu = cellwise(msh, original, E / (2 * (1 + nu)))
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 2))
    block = match_nodes(V, nodes)
    times["t_setup"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    eps = lambda w: ufl.sym(ufl.grad(w))  # noqa: E731
    a = fem.form(ufl.inner(2 * mu * eps(u) + lam * ufl.tr(eps(u)) * ufl.Identity(3), eps(v)) * ufl.dx)
    fixed = np.sort(block[data["fixed_nodes"]]).astype(np.int32)
    bc = fem.dirichletbc(np.zeros(3, dtype=PETSc.ScalarType), fixed, V)
    A = fpetsc.assemble_matrix(a, bcs=[bc])
    A.assemble()
    b = A.createVecRight()
    load = np.zeros((len(nodes), 3))
    load[block] = data["static_force"].reshape(-1, 3)
    b.array[:] = load.ravel()
    fpetsc.set_bc(b, [bc])
    times["t_assemble"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if args.solver == "gamg":
        A.setNearNullSpace(rigid_body_modes(V))
    options = PETSc.Options()
    for key, value in SOLVER_OPTIONS[args.solver].items():
        options[key] = value
    ksp = PETSc.KSP().create(MPI.COMM_SELF)
    ksp.setOperators(A)
    ksp.setFromOptions()
    ksp.setUp()
    times["t_factor"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    x = A.createVecLeft()
    ksp.solve(b, x)
    times["t_solve"] = time.perf_counter() - t0
    if ksp.getConvergedReason() <= 0:
        raise SystemExit(f"{args.solver} did not converge (reason {ksp.getConvergedReason()})")
    u_femstudy = x.array.reshape(-1, 3)[block].ravel()
    np.savez(args.out, u=u_femstudy, iterations=ksp.getIterationNumber(), solver=args.solver,
             n_dofs=V.dofmap.index_map.size_global * 3, **times)
    print(f"dolfinx {args.solver}: {3 * len(nodes)} DOFs, {ksp.getIterationNumber()} iterations, "
          + ", ".join(f"{k[2:]} {t:.2f} s" for k, t in times.items()))


if __name__ == "__main__":
    main()
