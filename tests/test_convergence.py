"""Observed order, Richardson extrapolation and GCI (Celik et al. 2008 procedure)."""

import math

import pytest

from femstudy.sweep.convergence import assess, coarsest_meeting_target, observed_order


def exact_series(h, phi0=1.0, c=0.3, p=2.0):
    return [phi0 + c * x ** p for x in h]


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_recovers_order_and_limit_for_uneven_ratios(p):
    h = [1.0, 1.7, 2.3]  # r21 = 1.7, r32 = 1.35: the iteration is needed
    values = exact_series(h, p=p)
    assert observed_order(values, h) == pytest.approx(p, rel=1e-8)
    a = assess("q", h, values, expected_order=p)
    assert a.verdict == "converging"
    assert a.extrapolated == pytest.approx(1.0, rel=1e-10)
    # GCI of the fine mesh bounds its true error here (exact asymptotic data)
    true_error = abs(values[0] - 1.0) / values[0]
    assert a.gci_fine == pytest.approx(1.25 * true_error, rel=1e-6)


def test_celik_worked_example():
    """Celik et al. 2008, Table 1, column phi = dimensionless reattachment length:
    N = 18000, 8000, 4500 cells; phi = 6.063, 5.972, 5.863; p = 1.53, phi_ext = 6.1685,
    GCI_fine = 2.17 %. h is (1/N)^(1/2) in 2-D."""
    h = [(1 / n) ** 0.5 for n in (18000, 8000, 4500)]
    a = assess("x_r", h, [6.063, 5.972, 5.863], expected_order=2)
    assert a.observed_order == pytest.approx(1.53, abs=0.01)
    assert a.extrapolated == pytest.approx(6.1685, abs=2e-3)
    assert a.gci_fine == pytest.approx(0.0217, abs=3e-4)


def test_singular_quantity_is_not_converging():
    h = [1.0, 2.0, 4.0]
    values = [10 * x ** -0.5 for x in h]  # grows as h -> 0
    a = assess("vm_peak", h, values, expected_order=2, singular_hint=True)
    assert a.verdict == "not converging"
    assert "singular" in a.reason


def test_oscillation_is_flagged():
    a = assess("q", [1.0, 2.0, 4.0], [1.0, 1.1, 1.05], expected_order=2)
    assert a.verdict == "not converging" and "alternates" in a.reason


def test_very_low_order_is_not_trusted():
    h = [1.0, 2.0, 4.0]
    values = [5 - 0.2 * x ** 0.2 for x in h]
    a = assess("q", h, values, expected_order=3)
    assert a.verdict == "not converging" and "far below" in a.reason


def test_coarsest_size_meeting_a_target():
    h = [4, 8, 16, 32]
    values = [1.000, 0.995, 0.975, 0.90]
    assert coarsest_meeting_target(h, values, 1.0, 0.02)[0] == 8
    size, error = coarsest_meeting_target(h, values, 1.0, 0.03)
    assert size == 16 and math.isclose(error, 0.025)


def test_sub_resolution_changes_are_converged_not_diverging():
    """The built-in femur's P2 max deflection at 6, 8 and 12 mm: changes of 0.1-0.3 %, growing
    under refinement; below the remeshing resolution that is convergence, not divergence."""
    a = assess("max_deflection_mm", [2.024, 2.412, 3.032], [0.053851, 0.053996, 0.054047], expected_order=3)
    assert a.verdict == "converged" and a.gci_fine == pytest.approx(0.0036, abs=1e-4)
    b = assess("max_deflection_mm", [2.024, 2.412, 3.032], [0.0501, 0.0488, 0.0465], expected_order=2)
    assert b.verdict == "converging"


def test_slow_order_on_a_singular_peak_is_not_convergence():
    """P2 peak von Mises under the patch, 6/8/12 mm: observed order 0.74 against a formal 2."""
    a = assess("max_von_mises_MPa", [2.024, 2.412, 3.032], [60.348, 53.122, 42.162], expected_order=2,
               singular_hint=True)
    assert a.verdict == "not converging" and "singular" in a.reason


def test_equal_finest_values_with_a_different_coarse_one_is_not_an_order():
    a = assess("q", [1.0, 1.5, 2.25], [1.0, 1.0, 1.2], expected_order=2)
    assert a.verdict == "not converging" and a.observed_order is None
    assert coarsest_meeting_target([1.0, 2.0], [0.0, 0.0], 0.0, 0.02) is None  # an unloaded bone
