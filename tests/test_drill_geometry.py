"""Drill geometry (Appendix A) and the derivation of the wall contact length l_w."""

import csv
from importlib import resources

import numpy as np
import pytest

from femstudy.drilling.drill import (DERIVED_WALL_LENGTH_MM, Drill, feed_per_revolution,
                                     wall_length_from_growth_exponent)
from femstudy.drilling.friction import builtin_bone_set
from femstudy.errors import UserError


def test_cone_length_eq_a1():
    assert Drill().cone_length_mm == pytest.approx(1.35, abs=1e-12)
    assert Drill(point_angle_deg=118).cone_length_mm == pytest.approx(1.35 / np.tan(np.radians(59)))


def test_feed_per_revolution():
    assert feed_per_revolution(2.0, 1500) == pytest.approx(0.08)
    assert feed_per_revolution(1.5, 1500) == pytest.approx(0.06)


def test_wall_length_derived_from_appendix_b_and_the_bovine_power_law():
    text = resources.files("femstudy.drilling").joinpath("data", "appendix_b_normality_trials.csv").read_text()
    rows = list(csv.DictReader(line for line in text.splitlines() if not line.startswith("#")))
    p_mean = np.mean([float(r["growth_exponent_p"]) for r in rows])
    assert p_mean == pytest.approx(0.469324333, abs=1e-9)  # thesis Table B-3
    mu_f, mu_w = builtin_bone_set("bovine").friction(1.5, 1500)
    l_w = wall_length_from_growth_exponent(p_mean, mu_f, mu_w)
    assert l_w == pytest.approx(DERIVED_WALL_LENGTH_MM, abs=5e-4)
    assert Drill().wall_mm == DERIVED_WALL_LENGTH_MM


@pytest.mark.parametrize("kwargs, message", [
    ({"point_angle_deg": 0}, "point angle"),
    ({"point_angle_deg": 180}, "point angle"),
    ({"point_angle_deg": -5}, "point angle"),
    ({"point_angle_deg": 5e-324}, "infinitely long"),   # its radians underflow: tan(β/2) = 0
    ({"diameter_mm": 0}, "diameter"),
    ({"wall_mm": -1}, "wall_mm"),
])
def test_bad_geometry_is_refused(kwargs, message):
    with pytest.raises(UserError, match=message):
        Drill(**kwargs)


@pytest.mark.parametrize("feed, rpm", [(0, 1500), (-1, 1500), (2, 0), (2, -1500), (float("nan"), 1500)])
def test_bad_operating_point_is_refused(feed, rpm):
    with pytest.raises(UserError):
        feed_per_revolution(feed, rpm)
