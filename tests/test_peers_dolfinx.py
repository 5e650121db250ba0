"""The DOLFINx benchmark runner (bench/peers/dolfinx_static.py) solves femstudy's discrete
problem: loads go in and displacements come out in femstudy's node order, whatever that is.

Runs only where Debian's python3-dolfinx is installed (bench/peers/setup.sh). femstudy's nodes
are shuffled before export so that the coordinate matching, not a coincidence of numbering,
carries the load and the answer. Tolerance 1e-8: both sides solve the same linear system with
a direct solver, so only round-off separates them.
"""

from __future__ import annotations

import subprocess
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from skfem import Basis, ElementTetP2, ElementVector, FacetBasis, LinearForm, MeshTet
from skfem.models.elasticity import lame_parameters, linear_elasticity

from femstudy.export.p2 import p2_layout

REPO = Path(__file__).resolve().parents[1]
SYSTEM_PYTHON = "/usr/bin/python3"
E_MPA = {1: 16000.0, 2: 500.0}
NU = {1: 0.4, 2: 0.15}


@lru_cache(maxsize=1)
def dolfinx_available() -> bool:
    try:
        probe = "import importlib.util, sys; sys.exit(importlib.util.find_spec('dolfinx') is None)"
        return subprocess.run([SYSTEM_PYTHON, "-c", probe], capture_output=True, timeout=60).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


@pytest.mark.skipif(not dolfinx_available(), reason="DOLFINx (python3-dolfinx) is not installed")
@pytest.mark.parametrize("solver, tolerance", [("mumps", 1e-8), ("gamg", 1e-7)])
def test_dolfinx_solves_the_exported_problem_in_femstudy_order(tmp_path, solver, tolerance):
    mesh = MeshTet.init_tensor(np.linspace(0, 30, 4), np.linspace(0, 6, 3), np.linspace(0, 6, 3))
    basis = Basis(mesh, ElementVector(ElementTetP2()))
    region = np.where(mesh.p[0, mesh.t].mean(axis=0) < 15, 1, 2)
    K = sum(linear_elasticity(*lame_parameters(E_MPA[c], NU[c])).assemble(
        basis.with_elements(np.flatnonzero(region == c))) for c in (1, 2))
    end = FacetBasis(mesh, basis.elem, facets=mesh.facets_satisfying(lambda x: x[0] == 30))
    force = LinearForm(lambda v, w: 0.3 * v[0] - v[1] + 0.5 * v[2] * (w.x[1] - 3)).assemble(end)
    fixed = basis.get_dofs(lambda x: x[0] == 0).flatten()
    free = np.setdiff1d(np.arange(basis.N), fixed)
    u = np.zeros(basis.N)
    u[free] = spla.spsolve(K.tocsr()[free][:, free].tocsc(), force[free])

    nodes, elements = p2_layout(basis)
    order = np.random.default_rng(7).permutation(len(nodes))      # new node k is old node order[k]
    new_index = np.argsort(order)
    dof = (3 * order[:, None] + np.arange(3)).ravel()                # new DOF -> old DOF
    np.savez(tmp_path / "case.npz", nodes=nodes[order], elements=new_index[elements], region=region,
             material_codes=np.array([1, 2]), youngs_modulus_MPa=np.array([E_MPA[1], E_MPA[2]]),
             poissons_ratio=np.array([NU[1], NU[2]]), fixed_nodes=np.unique(new_index[fixed // 3]),
             static_force=force[dof])
    proc = subprocess.run([SYSTEM_PYTHON, str(REPO / "bench/peers/dolfinx_static.py"), "case.npz", "out.npz",
                           "--solver", solver], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    u_dolfinx = np.load(tmp_path / "out.npz")["u"]
    assert np.abs(u_dolfinx - u[dof]).max() < tolerance * np.abs(u).max()
