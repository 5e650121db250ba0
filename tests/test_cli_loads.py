"""``femstudy loads`` end to end."""

import csv

import pytest

from conftest import assert_clean_failure, run_cli


def test_loads_prints_summary_and_writes_csv_and_plot(tmp_path):
    out_csv, out_png = tmp_path / "h.csv", tmp_path / "h.png"
    proc = run_cli("loads", "--feed", "2.0", "--rpm", "1500", "--csv", str(out_csv), "--plot", str(out_png))
    assert proc.returncode == 0, proc.stderr
    assert "mu_f = 0.2131" in proc.stdout and "a    = 0.0800 mm/rev" in proc.stdout
    for model in ("allotta", "clogging", "chi", "peng"):
        assert model in proc.stdout
    rows = list(csv.DictReader(out_csv.open()))
    assert set(rows[0]) == {"model", "time_s", "depth_mm", "thrust_N", "torque_Nmm"}
    assert {r["model"] for r in rows} == {"allotta", "clogging", "chi", "peng"}
    assert out_png.stat().st_size > 20_000


def test_extrapolation_is_warned():
    """The bovine law stays tame outside its box: warned; the human one, steep, is refused
    where its loads leave what a drill exerts (tests/test_hardening.py)."""
    proc = run_cli("loads", "--feed", "4.0", "--rpm", "3000", "--bone", "bovine")
    assert proc.returncode == 0
    assert "outside the conditions" in proc.stderr


@pytest.mark.parametrize("args, message", [
    (["--feed", "0", "--rpm", "1500"], "argument --feed: 0 mm/s is out of range: expected at least 0.01"),
    (["--feed", "-2", "--rpm", "1500"], "argument --feed: -2 mm/s is out of range"),
    (["--feed", "2", "--rpm", "0"], "argument --rpm: 0 rpm is out of range: expected at least 10"),
    (["--feed", "2", "--rpm", "1500", "--point-angle", "180"], "argument --point-angle: 180 degrees is out of range"),
    (["--feed", "2", "--rpm", "1500", "--point-angle", "0"], "argument --point-angle: 0 degrees is out of range"),
    (["--feed", "2", "--rpm", "1500", "--cortex-mm", "0"], "argument --cortex-mm: 0 mm is out of range"),
    (["--feed", "2", "--rpm", "1500", "--bone", "goat"], "unknown bone coefficient set 'goat'"),
    (["--feed", "fast", "--rpm", "1500"], "argument --feed: expected a number, got 'fast'"),
])
def test_bad_input_exits_2_with_one_clear_line(args, message):
    proc = run_cli("loads", *args)
    assert proc.returncode == 2
    assert_clean_failure(proc, message)
    assert len(proc.stderr.strip().splitlines()) == 1


def test_output_piped_into_a_reader_that_stops_early_is_not_a_traceback():
    import subprocess
    import sys

    proc = subprocess.run(f"'{sys.executable}' -m femstudy loads --feed 2 --rpm 1500 | head -n 1",
                          shell=True, capture_output=True, text=True)
    assert proc.stdout.startswith("drilling:")
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr
