"""Observed order, Richardson extrapolation and GCI (Celik et al. 2008; order cap and safety
factors of Oberkampf & Roy 2010), and the verdicts on synthetic sequences."""

import math

import pytest

from femstudy.convergence import GCI_CONVERGED, assess, coarsest_meeting_target, observed_order


def exact_series(h, phi0=1.0, c=0.3, p=2.0):
    return [phi0 + c * x ** p for x in h]


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_recovers_order_and_limit_for_uneven_ratios(p):
    h = [1.0, 1.7, 2.3]  # r21 = 1.7, r32 = 1.35: the iteration is needed
    values = exact_series(h, p=p)
    assert observed_order(values, h) == pytest.approx(p, rel=1e-8)
    a = assess("q", h, values, formal_order=p)
    assert a.verdict in ("converged", "converging") and a.order_used == pytest.approx(p, rel=1e-8)
    assert a.extrapolated == pytest.approx(1.0, rel=1e-10)
    # GCI of the fine mesh bounds its true error here (exact asymptotic data)
    true_error = abs(values[0] - 1.0) / values[0]
    assert a.gci_fine == pytest.approx(1.25 * true_error, rel=1e-6)


def test_celik_worked_example():
    """Celik et al. 2008, Table 1, column phi = dimensionless reattachment length:
    N = 18000, 8000, 4500 cells; phi = 6.063, 5.972, 5.863; p = 1.53, phi_ext = 6.1685,
    GCI_fine = 2.17 % (with p not capped: formal order 2, F_s 1.25 as in the paper)."""
    h = [(1 / n) ** 0.5 for n in (18000, 8000, 4500)]
    a = assess("x_r", h, [6.063, 5.972, 5.863], formal_order=1.6)
    assert a.observed_order == pytest.approx(1.53, abs=0.01)
    assert a.extrapolated == pytest.approx(6.1685, abs=2e-3)
    assert a.gci_fine == pytest.approx(0.0217, abs=3e-4)
    assert a.verdict == "converged"


def test_converged_sequence_at_the_formal_order():
    h = [0.5, 0.75, 1.125]
    a = assess("vm_at_1mm", h, exact_series(h, phi0=20.0, c=0.4, p=2.0), formal_order=2)
    assert a.verdict == "converged" and a.gci_fine < GCI_CONVERGED
    assert "above" not in a.reason


def test_super_convergent_order_is_capped_and_flagged():
    """Observed order 4 where the element gives 2: GCI with p = 2 and F_s = 3, flagged."""
    h = [0.5, 0.75, 1.125]
    values = exact_series(h, phi0=10.0, c=0.05, p=4.0)
    a = assess("q", h, values, formal_order=2)
    assert a.observed_order == pytest.approx(4.0, rel=1e-6) and a.order_used == 2
    assert "above the formal order" in a.reason and "safety factor 3" in a.reason
    r21 = 1.5
    assert a.gci_fine == pytest.approx(3.0 * abs(values[0] - values[1]) / values[0] / (r21 ** 2 - 1), rel=1e-12)
    # the uncapped GCI would have claimed about a tenth of that
    assert a.gci_fine > 5 * 1.25 * abs(values[0] - values[1]) / values[0] / (r21 ** 4 - 1)


def test_no_verdict_is_converged_at_an_order_above_the_formal_one():
    """An observed order of 4 against the element's 2 means the meshes are not in the asymptotic
    range: even a GCI under 5 % makes it "converging" (a band), not "converged"."""
    h = [0.5, 0.75, 1.125]
    a = assess("q", h, exact_series(h, phi0=10.0, c=0.01, p=4.0), formal_order=2)
    assert a.observed_order > 2.2 and a.gci_fine < GCI_CONVERGED
    assert a.verdict == "converging" and "not in the asymptotic range" in a.reason


@pytest.mark.parametrize("values", [[10 * x ** -0.5 for x in (1.0, 2.0, 4.0)],  # grows as h -> 0
                                    [59.0, 50.8, 30.6],  # looked like order 9 on 8/12/16 mm meshes
                                    [20.0, 20.001, 20.002]])  # even when it barely moves
def test_a_singular_quantity_is_never_converged(values):
    a = assess("vm_peak", [1.0, 2.0, 4.0], values, formal_order=2, singular=True)
    assert a.verdict == "singular" and "never converged" in a.reason and a.gci_fine is None


def test_changes_within_the_measured_remeshing_noise_are_convergence():
    """The built-in femur's P2 max deflection at 6, 8 and 12 mm: 0.1-0.3 % changes, growing
    under refinement. Against a measured remeshing noise of 0.4 % they are no change; with no
    noise they are divergence."""
    h, v = [2.024, 2.412, 3.032], [0.053851, 0.053996, 0.054047]
    a = assess("max_deflection_mm", h, v, formal_order=3, noise=0.004)
    assert a.verdict == "converged" and a.gci_fine == 0.004 and "noise" in a.reason  # the noise bounds it
    b = assess("max_deflection_mm", h, v, formal_order=3, noise=0.0)
    assert b.verdict == "not converging" and "diverging" in b.reason


def test_agreement_within_a_large_noise_is_not_convergence_to_five_percent():
    """The femoral neck's hole stress 1 mm from the wall: 9.36, 9.823, 10.08 MPa on three hole
    refinements, against an 11.1 % placement noise. They agree within the noise, but that is no
    evidence of convergence to 5 %; nor is a 2.8 % spread inside an 8 % noise."""
    a = assess("hole_1mm", [0.2, 0.3, 0.45], [9.36, 9.823, 10.08], formal_order=2, noise=0.111)
    assert a.verdict == "converging" and a.gci_fine == 0.111
    b = assess("hole_5mm", [0.2, 0.3, 0.45], [2.388, 2.383, 2.448], formal_order=2, noise=0.0807)
    assert b.verdict == "converging" and b.gci_fine == 0.0807


def test_oscillation_beyond_the_noise_is_flagged():
    a = assess("q", [1.0, 2.0, 4.0], [1.0, 1.1, 1.05], formal_order=2, noise=0.01)  # swing grows: R = -2
    assert a.verdict == "not converging" and "does not shrink" in a.reason


@pytest.mark.parametrize("values, verdict, uncertainty", [
    ([5.984, 6.012, 5.942], "converged", 0.5 * 0.070 / 5.984),  # the hole's 1 mm measure on the built-in femur
    ([10.0, 11.0, 9.0], "converging", 0.1),                       # swing shrinks but spans 20 %
])
def test_a_shrinking_oscillation_converges_with_half_its_range_as_uncertainty(values, verdict, uncertainty):
    a = assess("q", [0.2, 0.3, 0.45], values, formal_order=2, noise=0.001)
    assert -1 < a.ratio_R < 0
    assert a.verdict == verdict and a.gci_fine == pytest.approx(uncertainty, rel=1e-9)
    assert a.extrapolated is None and "oscillatory convergence" in a.reason


def test_very_low_order_is_not_trusted():
    h = [1.0, 2.0, 4.0]
    values = [5 - 0.2 * x ** 0.2 for x in h]
    a = assess("q", h, values, formal_order=3)
    assert a.verdict == "not converging" and "far below" in a.reason


def test_coarsest_size_meeting_a_target():
    h = [4, 8, 16, 32]
    values = [1.000, 0.995, 0.975, 0.90]
    assert coarsest_meeting_target(h, values, 1.0, 0.02)[0] == 8
    size, error = coarsest_meeting_target(h, values, 1.0, 0.03)
    assert size == 16 and math.isclose(error, 0.025)


def test_equal_finest_values_with_a_different_coarse_one_is_not_an_order():
    a = assess("q", [1.0, 1.5, 2.25], [1.0, 1.0, 1.2], formal_order=2)
    assert a.verdict == "not converging" and a.observed_order is None
    assert coarsest_meeting_target([1.0, 2.0], [0.0, 0.0], 0.0, 0.02) is None  # an unloaded bone


def test_an_oscillatory_converged_deflection_recommends_a_size_against_the_finest_value():
    """The TLEM 2.0 sweep 8, 6, 4.5 mm: the max deflection converges with a shrinking swing,
    which gives no extrapolated value; the recommendation is then made against the finest
    mesh's value (and says so), not refused."""
    from femstudy.sweeps.report import convergence, convergence_markdown

    rows = [{"order": 2, "refine": "site", "size_mm": s, "h_rep_mm": h, "max_deflection_mm": v}
            for s, h, v in ((8, 2.257, 0.04319), (6, 1.846, 0.04299), (4.5, 1.587, 0.0431), (6, 1.888, 0.04305))]
    quantities = {"max_deflection_mm": (1, 3, False, False)}
    entry = convergence(rows, 0.02, quantities)["P2-site"]
    assert entry["quantities"]["max_deflection_mm"]["verdict"] == "converged"
    assert entry["quantities"]["max_deflection_mm"]["extrapolated"] is None
    assert entry["recommended_reference"] == "finest" and entry["recommended_size_mm"] == 8
    assert entry["recommended_error"] == pytest.approx(abs(0.04319 / 0.0431 - 1))
    assert "the finest mesh's value" in convergence_markdown({"P2-site": entry}, 0.02)


def test_an_order_equation_without_solution_is_no_order_not_an_overflow():
    """Unequal refinement ratios (1.047, 1.104) and changes that barely shrink (P1 deflections of
    a 32, 24, 16 mm sweep): the fixed-point iteration for the order diverges; that is no observed
    order, and the sequence does not converge."""
    h = (2.9781993911859557, 3.1189614610430145, 3.444852377043569)
    values = (0.03015182647714923, 0.02975266638793374, 0.029303723398175368)
    assert observed_order(values, h) is None
    assert assess("max_deflection_mm", h, values, formal_order=2.0).verdict == "not converging"
