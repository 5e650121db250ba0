"""The failure criteria: Tsai–Wu for the cortex reproduces each Table 2-4 strength, and the
strength ratio scales inversely with the load."""

import numpy as np
import pytest

from femstudy import thesis
from femstudy.failure import CorticalStrength, cancellous_strength_ratio, cortical_strength_ratio

AXIS = np.array([0.0, 0.0, 1.0])
S = thesis.CORTICAL_STRENGTH_MPA


@pytest.mark.parametrize("stress, strength", [
    ([0, 0, 1, 0, 0, 0], S["longitudinal_tension_ultimate"]),
    ([0, 0, -1, 0, 0, 0], S["longitudinal_compression_ultimate"]),
    ([1, 0, 0, 0, 0, 0], S["transverse_tension_ultimate"]),
    ([0, -1, 0, 0, 0, 0], S["transverse_compression_ultimate"]),
    ([0, 0, 0, 1, 0, 0], S["shear_ultimate"]),  # τ on a plane containing the long axis
])
def test_each_uniaxial_strength_is_met_exactly(stress, strength):
    """A unit stress of each kind fails at the table's strength: λ = strength."""
    assert cortical_strength_ratio(np.array(stress, float), AXIS)[()] == pytest.approx(strength, rel=1e-12)


def test_the_frame_follows_the_long_axis_and_the_ratio_the_load():
    axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    sigma = 40.0 * np.outer(axis, axis)  # 40 MPa tension along the tilted axis
    voigt = np.array([sigma[0, 0], sigma[1, 1], sigma[2, 2], sigma[1, 2], sigma[0, 2], sigma[0, 1]])
    ratio = cortical_strength_ratio(voigt, axis)
    assert ratio == pytest.approx(S["longitudinal_tension_ultimate"] / 40.0, rel=1e-12)
    random = np.random.default_rng(0).normal(scale=20.0, size=(50, 6))
    np.testing.assert_allclose(cortical_strength_ratio(3 * random, AXIS), cortical_strength_ratio(random, AXIS) / 3,
                               rtol=1e-12)
    assert np.isinf(cortical_strength_ratio(np.zeros(6), AXIS))


def test_biaxial_tension_is_weaker_than_either_alone_by_the_interaction():
    """Transverse tension plus longitudinal tension: the interaction term lowers neither below
    the weaker alone, and the criterion stays convex (the ratio of the sum at most the
    harmonic-like bound)."""
    both = cortical_strength_ratio(np.array([30.0, 0, 60.0, 0, 0, 0]), AXIS)
    alone = min(cortical_strength_ratio(np.array([30.0, 0, 0, 0, 0, 0]), AXIS),
                cortical_strength_ratio(np.array([0, 0, 60.0, 0, 0, 0]), AXIS))
    assert 0.5 * alone < both <= 1.5 * alone


def test_cancellous_ratio_and_source():
    assert cancellous_strength_ratio(np.array([3.78]))[0] == pytest.approx(2.0)
    assert CorticalStrength().source.startswith("thesis Table 2-4")
