"""The CalculiX export: C3D10 node order, load blocks, and (when ``ccx`` is installed) the same
answers as scikit-fem on a tiny clamped two-material beam.

Tolerances: the static field agrees to 1e-6 relative — identical discretisation, exact
stiffness quadrature on both sides; the .dat file's 7 significant digits (≤ 5e-7 relative to
the largest value) are the floor. The transient uses Newmark average acceleration on both
sides with the 4-point mass rule of C3D10, so it agrees to the same 1e-6.
"""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from skfem import Basis, BilinearForm, ElementTetP2, ElementVector, FacetBasis, LinearForm, MeshTet
from skfem.helpers import dot
from skfem.models.elasticity import lame_parameters, linear_elasticity

from femstudy.errors import UserError
from femstudy.export.calculix import (DynamicStep, Isotropic, StaticStep, c3d10_connectivity,
                                      read_dat_displacements, run_ccx, write_inp)
from femstudy.export.p2 import p2_layout

#: C3D10 nodes 5–10 (1-based) sit on the edges (1,2), (2,3), (3,1), (1,4), (2,4), (3,4).
C3D10_EDGES = np.array([[1, 2], [2, 3], [3, 1], [1, 4], [2, 4], [3, 4]]) - 1
MATERIALS = {1: Isotropic(16000.0, 0.4, 1.7e-9), 2: Isotropic(500.0, 0.15, 3.2e-10)}
DIRECTION = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
needs_ccx = pytest.mark.skipif(shutil.which("ccx") is None, reason="CalculiX (ccx) is not installed")


@pytest.fixture(scope="module")
def beam():
    """A 40 × 8 × 8 mm cantilever (x = 0 clamped), stiff half at x < 20, soft half beyond;
    an oblique end traction (1 N) and a twisting one (1 N·mm about x) on the x = 40 face."""
    mesh = MeshTet.init_tensor(np.linspace(0, 40, 5), np.linspace(0, 8, 3), np.linspace(0, 8, 3))
    basis = Basis(mesh, ElementVector(ElementTetP2()))
    region = np.where(mesh.p[0, mesh.t].mean(axis=0) < 20, 1, 2)
    K = M = 0
    for code, mat in MATERIALS.items():
        cells = np.flatnonzero(region == code)
        K = K + linear_elasticity(*lame_parameters(mat.youngs_modulus_MPa, mat.poissons_ratio)).assemble(
            basis.with_elements(cells))
        M = M + BilinearForm(lambda u, v, w, rho=mat.density_t_mm3: rho * dot(u, v)).assemble(
            Basis(mesh, basis.elem, elements=cells, intorder=2))
    end = FacetBasis(mesh, basis.elem, facets=mesh.facets_satisfying(lambda x: x[0] == 40))
    thrust = LinearForm(lambda v, w: dot(v, DIRECTION[:, None, None]) / 64).assemble(end)
    polar = 64 * (16 + 16) / 3          # ∫ (y−4)² + (z−4)² dA over the 8 × 8 face [mm⁴]
    torque = LinearForm(lambda v, w: (-(w.x[2] - 4) * v[1] + (w.x[1] - 4) * v[2]) / polar).assemble(end)
    fixed = basis.get_dofs(lambda x: x[0] == 0).flatten()
    nodes, elements = p2_layout(basis)
    return dict(basis=basis, K=K.tocsr(), M=M.tocsr(), region=region, thrust=thrust, torque=torque,
                fixed=fixed, free=np.setdiff1d(np.arange(basis.N), fixed), nodes=nodes, elements=elements)


def test_p2_layout_is_the_c3d10_node_order(beam):
    nodes, c3d10 = beam["nodes"], c3d10_connectivity(beam["nodes"], beam["elements"]) - 1
    x = nodes[c3d10]
    midpoints = (x[:, C3D10_EDGES[:, 0]] + x[:, C3D10_EDGES[:, 1]]) / 2
    np.testing.assert_allclose(x[:, 4:], midpoints, atol=1e-12)
    volume = np.linalg.det(np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=2))
    assert np.all(volume > 0)


def test_negative_elements_are_flipped_with_their_edges():
    vertices = np.array([[0.0, 0, 0], [0, 1, 0], [1, 0, 0], [0, 0, 1]])     # det < 0
    edges = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
    nodes = np.vstack([vertices, [(vertices[a] + vertices[b]) / 2 for a, b in edges]])
    c3d10 = c3d10_connectivity(nodes, np.arange(10)[None]) - 1
    x = nodes[c3d10[0]]
    assert np.linalg.det(np.array([x[1] - x[0], x[2] - x[0], x[3] - x[0]])) > 0
    np.testing.assert_allclose(x[4:], (x[C3D10_EDGES[:, 0]] + x[C3D10_EDGES[:, 1]]) / 2)


def test_overlapping_patterns_load_each_dof_once(beam, tmp_path):
    """CalculiX refuses two concentrated loads with different amplitudes on one DOF."""
    assert np.count_nonzero((beam["thrust"] != 0) & (beam["torque"] != 0)) > 0
    times = np.linspace(0, 1e-4, 6)
    step = DynamicStep([beam["thrust"], beam["torque"]], times, [times * 1e6, times * 2e6], 2e-5, 1e-4)
    deck = write_inp(tmp_path / "d.inp", beam["nodes"], beam["elements"], beam["region"], MATERIALS,
                     np.unique(beam["fixed"] // 3), [step]).read_text()
    cloads = deck[deck.index("*STEP"):]
    pairs = re.findall(r"^(\d+), (\d), ", cloads, flags=re.M)
    assert len(pairs) == len(set(pairs)) == np.count_nonzero((beam["thrust"] != 0) | (beam["torque"] != 0))


def test_missing_material_is_a_user_error(beam, tmp_path):
    with pytest.raises(UserError, match="no material given for region code"):
        write_inp(tmp_path / "x.inp", beam["nodes"], beam["elements"], beam["region"], {1: MATERIALS[1]},
                  np.unique(beam["fixed"] // 3), [StaticStep(beam["thrust"])])


def _relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@needs_ccx
def test_calculix_static_equals_scikit_fem(beam, tmp_path):
    force = 80.0 * beam["thrust"] + 150.0 * beam["torque"]
    free = beam["free"]
    u = np.zeros(beam["basis"].N)
    u[free] = spla.spsolve(beam["K"][free][:, free].tocsc(), force[free])
    write_inp(tmp_path / "static.inp", beam["nodes"], beam["elements"], beam["region"], MATERIALS,
              np.unique(beam["fixed"] // 3), [StaticStep(force)])
    run_ccx(tmp_path / "static.inp")
    result = read_dat_displacements(tmp_path / "static.dat")
    assert _relative(result.dof_vector(0, len(beam["nodes"])), u) < 1e-6


@needs_ccx
def test_calculix_dynamic_equals_newmark_with_the_four_point_mass(beam, tmp_path):
    dt, steps = 2e-5, 10
    times = np.arange(steps + 1) * dt
    thrust_N = np.interp(times, [0, 1e-4, 1], [0, 80, 80])
    torque_Nmm = np.interp(times, [0, 2e-4, 1], [0, 150, 0])
    free = beam["free"]
    K, M = beam["K"][free][:, free].tocsc(), beam["M"][free][:, free].tocsc()
    patterns = np.column_stack([beam["thrust"][free], beam["torque"][free]])
    keff = spla.splu(K + 4 / dt**2 * M)
    u, v, a = np.zeros(len(free)), np.zeros(len(free)), np.zeros(len(free))
    history = []
    for n in range(1, steps + 1):           # Newmark average acceleration from rest, f(0) = 0
        u_new = keff.solve(patterns @ [thrust_N[n], torque_Nmm[n]] + M @ (4 / dt**2 * u + 4 / dt * v + a))
        a_new = 4 / dt**2 * (u_new - u) - 4 / dt * v - a
        v, u, a = v + dt / 2 * (a + a_new), u_new, a_new
        history.append(u.copy())
    step = DynamicStep([beam["thrust"], beam["torque"]], times, [thrust_N, torque_Nmm], dt, steps * dt)
    write_inp(tmp_path / "dynamic.inp", beam["nodes"], beam["elements"], beam["region"], MATERIALS,
              np.unique(beam["fixed"] // 3), [step])
    run_ccx(tmp_path / "dynamic.inp")
    result = read_dat_displacements(tmp_path / "dynamic.dat")
    np.testing.assert_allclose(result.times_s, times[1:], rtol=1e-6)
    ccx = np.array([result.dof_vector(k, len(beam["nodes"]))[free] for k in range(steps)])
    assert _relative(ccx, np.array(history)) < 1e-6
