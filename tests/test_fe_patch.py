"""Constant-strain patch test: a linear displacement field on the boundary of a distorted
mesh must be reproduced exactly inside, with exactly uniform stress D ε."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla
import skfem

from femstudy.materials import BoneMaterials
from femstudy.fe import assemble, element_stress
from femstudy.fe.materials import CORTICAL_TRANSVERSELY_ISOTROPIC, frame_with_axis, rotate_stiffness
from femstudy.femur_mesh import TetMesh

STRAIN = np.array([1e-3, -4e-4, 2.5e-4, 3e-4, -6e-4, 8e-4])  # Voigt, engineering shear
VOIGT_TO_TENSOR = [[0, 5, 4], [5, 1, 3], [4, 3, 2]]


def distorted_box() -> TetMesh:
    """A 30 × 20 × 10 mm box of 6·4·3·2 = 144 tets whose interior vertices are moved randomly."""
    m = skfem.MeshTet.init_tensor(np.linspace(0, 30, 5), np.linspace(0, 20, 4), np.linspace(0, 10, 3))
    p = m.p.copy()
    interior = np.setdiff1d(np.arange(m.nvertices), m.boundary_nodes())
    p[:, interior] += np.random.default_rng(4).uniform(-1.5, 1.5, (3, len(interior)))
    return TetMesh(p.T, m.t.T, np.ones(m.nelements, dtype=np.int8))


def linear_field(x: np.ndarray) -> np.ndarray:
    """u = ε x + ω × x + c with the strain STRAIN, a small rotation and a translation [mm]."""
    eps = np.array([[STRAIN[VOIGT_TO_TENSOR[i][j]] * (1 if i == j else 0.5) for j in range(3)] for i in range(3)])
    omega = np.array([2e-4, -1e-4, 3e-4])
    return x @ eps.T + np.cross(omega, x) + np.array([0.01, -0.02, 0.03])


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("model", ["isotropic", "transversely_isotropic"])
def test_linear_field_is_reproduced_to_round_off(order, model):
    system = assemble(distorted_box(), BoneMaterials(cortical_model=model), order=order,
                      long_axis=np.array([1.0, 2.0, 2.0]) / 3)
    exact = linear_field(system.nodes).ravel()
    boundary = np.unique(system.dofs.get_facet_dofs(system.mesh.boundary_facets()).flatten())
    interior = np.setdiff1d(np.arange(system.n_dofs), boundary)
    K = system.K.tocsr()
    rhs = -K[interior][:, boundary] @ exact[boundary]
    u = exact.copy()
    u[interior] = spla.spsolve(K[interior][:, interior].tocsc(), rhs)
    # round-off: 1e-10 relative to the displacement scale (solves of a ~1e4-conditioned system)
    assert np.abs(u - exact).max() < 1e-10 * np.abs(exact).max()
    D = system.materials.D[0]
    stress = element_stress(system, u)
    np.testing.assert_allclose(stress, np.broadcast_to(D @ STRAIN, stress.shape), atol=1e-9 * np.abs(D @ STRAIN).max())


def test_transversely_isotropic_cortex_is_oriented_along_the_long_axis():
    axis = np.array([0.0, 0.6, 0.8])
    system = assemble(distorted_box(), BoneMaterials(cortical_model="transversely_isotropic"), long_axis=axis)
    D = system.materials.D[0]
    expected = rotate_stiffness(CORTICAL_TRANSVERSELY_ISOTROPIC.stiffness(), frame_with_axis(axis))
    np.testing.assert_allclose(D, expected)
    # uniaxial stress σ along the axis stretches it by σ/E_L
    n = axis
    sigma = 100.0 * np.array([n[0] ** 2, n[1] ** 2, n[2] ** 2, n[1] * n[2], n[0] * n[2], n[0] * n[1]])
    strain = np.linalg.solve(D, sigma)
    along = strain[:3] @ n ** 2 + strain[3] * n[1] * n[2] + strain[4] * n[0] * n[2] + strain[5] * n[0] * n[1]
    assert along == pytest.approx(100.0 / CORTICAL_TRANSVERSELY_ISOTROPIC.E_L_MPa, rel=1e-12)
