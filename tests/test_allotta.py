"""Allotta cutting thrust and torque (Eqs 2.18-2.19) across the phases of a unicortical hole."""

import math

import numpy as np
import pytest

from femstudy.drilling import allotta
from femstudy.drilling.drill import Drill

A, H, U1, U2 = 0.08, 6.0, 448.5, 25.5
DRILL = Drill()
L = DRILL.cone_length_mm
SIN, TAN = math.sin(math.pi / 4), math.tan(math.pi / 4)


def F(d, u2=U2, drill=DRILL):
    return allotta.thrust(d, A, H, U1, u2, drill)


def T(d, u2=U2, drill=DRILL):
    return allotta.torque(d, A, H, U1, u2, drill)


def test_full_engagement_thrust_is_a_sin_tan_u1_l():
    assert F(3.0) == pytest.approx(A * SIN * TAN * U1 * L, rel=1e-14)
    assert allotta.full_engagement(A, U1)[0] == pytest.approx(A * SIN * TAN * U1 * L, rel=1e-14)


def test_full_engagement_torque_equals_eq_2_3():
    assert T(3.0) == pytest.approx(U1 * 2.7 ** 2 * A / 8, rel=1e-14)


@pytest.mark.parametrize("drill", [DRILL, Drill(point_angle_deg=118)])
@pytest.mark.parametrize("boundary", ["entry", "engaged", "breakthrough", "cancellous"])
def test_continuous_across_phase_boundaries(drill, boundary):
    l = drill.cone_length_mm
    d = {"entry": 0.0, "engaged": l, "breakthrough": H, "cancellous": H + l}[boundary]
    eps = 1e-9
    assert abs(F(d + eps, drill=drill) - F(d - eps, drill=drill)) < 1e-6
    assert abs(T(d + eps, drill=drill) - T(d - eps, drill=drill)) < 1e-6


def test_entry_thrust_linear_and_torque_parabolic():
    d = np.linspace(0, L, 11)
    np.testing.assert_allclose(F(d), A * SIN * TAN * U1 * d, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(T(d), A * TAN ** 2 * U1 * d ** 2 / 2, rtol=1e-13, atol=1e-13)
    # a parabola: constant, non-zero second difference
    second = np.diff(T(d), 2)
    np.testing.assert_allclose(second, second[0], rtol=1e-9)
    assert second[0] > 0


def test_transition_matches_eqs_2_18_and_2_19_with_x_b():
    d = np.linspace(H, H + L, 9)
    x_b = H - (d - L)  # cone length still in cortex, measured from the cone base
    f_expected = A * SIN * TAN * (U1 * x_b + U2 * (L - x_b))
    t_expected = A * TAN ** 2 * (U1 * x_b * (L - x_b / 2) + U2 / 2 * (L - x_b) ** 2)
    np.testing.assert_allclose(F(d), f_expected, rtol=1e-13)
    np.testing.assert_allclose(T(d), t_expected, rtol=1e-13)


def test_exit_into_air_falls_to_zero():
    assert F(H + L + 0.1, u2=0.0) == 0.0
    assert T(H + L + 0.1, u2=0.0) == 0.0
    assert F(-1.0) == 0.0 and T(-1.0) == 0.0


def test_thin_cortex_never_reaches_full_engagement():
    thin = allotta.thrust(np.linspace(0, 3, 301), A, 0.5, U1, U2)
    assert thin.max() < A * SIN * TAN * U1 * L
