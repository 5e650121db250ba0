"""Normality tests: Tables 4-2 and 4-3 reproduced from Appendix B, Shapiro-Wilk, median ranks."""

import numpy as np
import pytest

from conftest import run_cli
from femstudy.recordings.normality import appendix_b, chi_square_table, median_ranks, normality, probability_plot

# (observed, normal probability, expected, O - E, chi-square) per bin, as printed.
TABLE_4_2 = [(0, 0.023, 0.69, -0.69, 0.6900), (2, 0.044, 1.32, 0.68, 0.3503), (2, 0.092, 2.76, -0.76, 0.2093),
             (8, 0.15, 4.5, 3.5, 2.7222), (4, 0.191, 5.73, -1.73, 0.5223), (5, 0.191, 5.73, -0.73, 0.0930),
             (5, 0.15, 4.5, 0.5, 0.0556), (1, 0.092, 2.76, -1.76, 1.1223), (1, 0.044, 1.32, -0.32, 0.0776),
             (2, 0.023, 0.69, 1.31, 2.4871)]
TABLE_4_3 = [(2, 0.023, 0.69, 1.31, 2.4871), (0, 0.044, 1.32, -1.32, 1.3200), (2, 0.092, 2.76, -0.76, 0.2093),
             (4, 0.15, 4.5, -0.5, 0.0556), (4, 0.191, 5.73, -1.73, 0.5223), (8, 0.191, 5.73, 2.27, 0.8993),
             (6, 0.15, 4.5, 1.5, 0.5000), (4, 0.092, 2.76, 1.24, 0.5571), (0, 0.044, 1.32, -1.32, 1.3200),
             (0, 0.023, 0.69, -0.69, 0.6900)]


@pytest.mark.parametrize("column, printed, total", [(1, TABLE_4_2, 8.3297), (0, TABLE_4_3, 8.5606)],
                         ids=["Table 4-2 (F_o)", "Table 4-3 (p)"])
def test_chi_square_tables_reproduced_exactly_from_appendix_b(column, printed, total):
    values = appendix_b()[column]
    table = chi_square_table(values)
    for row, (o, p, e, d, c) in zip(table.rows, printed):
        assert row[1] == o
        assert row[2] == p
        assert round(row[3], 2) == e
        assert round(row[4], 2) == d
        assert round(row[5], 4) == c
    assert round(table.statistic, 4) == total
    assert table.dof == 7 and round(table.critical, 1) == 14.1 and table.normal


def test_standardisation_is_table_b_2s():
    p, F = appendix_b()
    assert F.mean() == pytest.approx(25.6861, abs=1e-4)
    assert F.std(ddof=1) == pytest.approx(3.592548998, abs=1e-9)   # Table B-2 "Sigma"
    assert p.std(ddof=1) == pytest.approx(0.097625435, abs=1e-9)   # Table B-3


def test_shapiro_wilk_finds_what_the_coarse_chi_square_misses():
    """Appendix B's p has two low trials (0.189, 0.271): Shapiro-Wilk rejects normality at 5 %
    where the thesis's ten-bin chi-square accepted it; F_o passes both."""
    p, F = appendix_b()
    assert normality("F_o", F).shapiro_p > 0.3
    res = normality("p", p)
    assert res.shapiro_p < 0.05 and res.chi_square.normal


def test_median_ranks_and_probability_plot():
    np.testing.assert_allclose(median_ranks(4), [0.7 / 4.4, 1.7 / 4.4, 2.7 / 4.4, 3.7 / 4.4])
    x = np.random.default_rng(1).normal(10, 2, 200)
    pp = probability_plot(x)
    assert pp.r > 0.99
    assert pp.slope == pytest.approx(2, rel=0.1) and pp.intercept == pytest.approx(10, abs=0.3)


def test_normality_command_prints_tables_4_2_and_4_3(tmp_path):
    proc = run_cli("normality", "--plot", str(tmp_path / "n.png"))
    assert proc.returncode == 0, proc.stderr
    assert "Table 4-2" in proc.stdout and "Table 4-3" in proc.stdout
    assert "sum 8.3297 < 14.1" in proc.stdout and "sum 8.5606 < 14.1" in proc.stdout
    assert (tmp_path / "n.png").stat().st_size > 20_000
