"""``femstudy diagnose`` end to end: outputs, the JSON contract, a simulation on another time base, and
bad input (one clear line, exit 2, nothing written)."""

import json
from dataclasses import replace

import numpy as np
import pytest

from conftest import assert_clean_failure, run_cli
from femstudy.recordings import (Effects, FeedPulsation, Noise, SpindleRipple, ThermalSoftening, synthesize,
                                 write_recording)

NUISANCE = dict(noise=Noise(0.3, 1.0), ripple=SpindleRipple(0.05), drift=None, softening=None)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A clogging recording with feed pulsation (1 kHz, 9.5 s); an Allotta and a clogging simulation
    at 250 Hz that start 1.5 s later and end 1 s earlier, torque in N·m."""
    folder = tmp_path_factory.mktemp("diagnose")
    rec = synthesize(1.5, 1500, mu_f=0.07, effects=Effects(**NUISANCE, pulsation=FeedPulsation(0.3, 1.2, 0.4)),
                     seed=5)
    write_recording(folder / "rec.csv", rec)
    quiet = synthesize(1.5, 1500, mu_f=0.07, effects=Effects(**NUISANCE, pulsation=None), seed=6)
    write_recording(folder / "quiet.csv", quiet)
    for model in ("allotta", "clogging"):
        sim = synthesize(1.5, 1500, mu_f=0.07, model=model, effects=Effects.none(), sample_rate_hz=250,
                         approach_s=0.5, tail_s=1.0)
        write_recording(folder / f"{model}.csv", replace(sim, time_s=sim.time_s + 1.5), torque_unit="Nm")
    return folder


def diagnose_json(tmp_path, *args):
    """``femstudy diagnose ARGS --json`` run to success: the process and the JSON it wrote."""
    out = tmp_path / "d.json"
    proc = run_cli("diagnose", *map(str, args), "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    return proc, json.loads(out.read_text())


def test_pulsation_and_clogging_found_against_an_allotta_trace_on_another_time_base(files, tmp_path):
    proc, js = diagnose_json(tmp_path, files / "rec.csv", "--simulation", files / "allotta.csv",
                             "--plot", tmp_path / "d.png", "--report", tmp_path / "report")
    assert sorted(m["mechanism"] for m in js["missing_physics"]) == ["chip_clogging", "feed_pulsation"]
    assert js["fit"]["improved"]["r2"] > 0.999 > js["fit"]["baseline"]["r2"]
    assert {m["channel"] for m in js["mismatch"]} == {"thrust_N", "torque_Nmm"}
    puls = next(m for m in js["missing_physics"] if m["mechanism"] == "feed_pulsation")["parameters"]
    assert puls["frequency_hz"] == pytest.approx(1.2, rel=0.01) and puls["amplitude"] == pytest.approx(0.3, rel=0.03)
    assert "chip_clogging" in proc.stdout and "implied flute friction" in proc.stdout
    assert "R2 " in proc.stdout and "held out" in proc.stdout and "consistent with the noise model" in proc.stdout
    assert (tmp_path / "d.png").stat().st_size > 30_000
    report = tmp_path / "report"
    assert {p.name for p in report.iterdir()} == {"report.md", "overlay.png", "residuals.png", "diagnosis.json",
                                                 ".femstudy.json"}  # the marker: femstudy may replace the folder
    assert "## Mechanisms" in (report / "report.md").read_text()
    assert json.loads((report / "diagnosis.json").read_text())["missing_physics"] == js["missing_physics"]


def test_one_worker_process_or_one_per_core_gives_the_same_diagnosis(files, tmp_path):
    """``--workers 1`` makes every fit in the command's own process; the default spreads them
    over the cores (§7 of docs/diagnosis.md). The JSON is the same but for the wall time."""
    _, spread = diagnose_json(tmp_path, files / "rec.csv", "--simulation", files / "allotta.csv", "--quiet")
    _, alone = diagnose_json(tmp_path, files / "rec.csv", "--simulation", files / "allotta.csv", "--quiet",
                             "--workers", "1")
    spread.pop("seconds"), alone.pop("seconds")
    assert spread == alone and spread["missing_physics"]


def test_complete_simulation_reports_nothing(files, tmp_path):
    proc, js = diagnose_json(tmp_path, files / "quiet.csv", "--simulation", files / "clogging.csv", "--quiet")
    assert js["missing_physics"] == [] and js["mismatch"] == []
    assert "missing physics: none" in proc.stdout and proc.stderr == ""


def _bad_files(folder):
    """Recordings and simulations that must be refused."""
    rec = synthesize(1.5, 1500, effects=Effects(**NUISANCE, pulsation=None), seed=1)
    write_recording(folder / "other_feed.csv", replace(rec, metadata={**rec.metadata, "feed_mm_s": 2.0}))
    write_recording(folder / "zero.csv", replace(rec, thrust_N=0 * rec.thrust_N, torque_Nmm=None))
    short = synthesize(1.5, 1500, effects=Effects.none(), approach_s=0.2, stop_depth_mm=1.0, tail_s=0.2)
    write_recording(folder / "short.csv", short)
    meta = {k: v for k, v in rec.metadata.items() if k != "spindle_rpm"}
    write_recording(folder / "no_rpm.csv", replace(rec, metadata=meta))


@pytest.mark.parametrize("args, message", [
    (["missing.csv", "--simulation", "{f}/clogging.csv"], "does not exist"),
    (["{f}/quiet.csv"], "one of the arguments --simulation --model is required"),
    (["{f}/quiet.csv", "--simulation", "{f}/clogging.csv", "--model", "allotta"], "not allowed with"),
    (["{f}/quiet.csv", "--simulation", "{f}/other_feed.csv"], "was computed for feed_mm_s = 2.0"),
    (["{f}/quiet.csv", "--simulation", "{f}/zero.csv"], "thrust_N is constant (0 N)"),
    (["{f}/short.csv", "--simulation", "{f}/short.csv"], "too short to diagnose"),
    (["{f}/no_rpm.csv", "--simulation", "{f}/clogging.csv"], "has no spindle_rpm"),
    (["{f}/quiet.csv", "--simulation", "{f}/clogging.csv", "--cortex-mm", "0"], "argument --cortex-mm: 0 mm is out of range"),
    (["{f}/quiet.csv", "--simulation", "{f}/clogging.csv", "--plot", "{out}.txt"], "--plot must end in"),
    (["{f}/quiet.csv", "--simulation", "{f}/clogging.csv", "--bone", "goat"], "unknown bone coefficient set"),
    (["{f}/quiet.csv", "--simulation", "{f}/clogging.csv", "--set", "feed_mm_s"], "--set expects KEY=VALUE"),
    (["{f}/quiet.csv", "--simulation", "{f}/clogging.csv", "--workers", "0"], "argument --workers: 0 is out of range"),
])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(files, tmp_path, args, message):
    if not (files / "short.csv").exists():
        _bad_files(files)
    out = tmp_path / "d"
    args = [a.format(f=files, out=out) for a in args] + ["--json", f"{out}.json", "--quiet"]
    proc = run_cli("diagnose", *args)
    assert proc.returncode == 2
    assert_clean_failure(proc, message)
    assert len(proc.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_no_torque_in_the_recording_diagnoses_thrust_alone(files, tmp_path):
    rec = synthesize(1.5, 1500, mu_f=0.07, effects=Effects(**NUISANCE, pulsation=None), seed=8)
    write_recording(tmp_path / "thrust_only.csv", replace(rec, torque_Nmm=None))
    _, js = diagnose_json(tmp_path, tmp_path / "thrust_only.csv", "--simulation", files / "allotta.csv", "--quiet")
    assert [m["mechanism"] for m in js["missing_physics"]] == ["chip_clogging"]
    assert set(js["fit"]["channels"]) == {"thrust_N"} and set(js["noise"]) == {"thrust_N"}
    assert np.isclose(js["noise"]["thrust_N"], 0.3, rtol=0.05)


def test_load_model_path_finds_softening_and_is_silent_when_complete(tmp_path):
    """--model: the bone set's load model from the detected contact; friction of the bone set."""
    quiet = synthesize(1.5, 1500, effects=Effects(**NUISANCE, pulsation=None), seed=9, approach_s=1.5)
    soft = synthesize(1.5, 1500, effects=Effects(**{**NUISANCE, "softening": ThermalSoftening(0.2, 1.5)},
                                                 pulsation=None), seed=10, approach_s=1.5)
    for name, rec, expected in (("quiet", quiet, []), ("soft", soft, ["thermal_softening"])):
        write_recording(tmp_path / f"{name}.csv", rec)
        proc, js = diagnose_json(tmp_path, tmp_path / f"{name}.csv", "--model", "clogging", "--quiet")
        assert [m["mechanism"] for m in js["missing_physics"]] == expected, js["selection"]
        assert "load model 'clogging'" in proc.stdout
    p = js["missing_physics"][0]["parameters"]
    assert p["fraction"] == pytest.approx(0.2, rel=0.1) and p["time_constant_s"] == pytest.approx(1.5, rel=0.25)


def test_simulation_without_a_header_takes_feed_and_speed_from_the_recording(files, tmp_path):
    """An FE trace as plain columns (no '#' metadata lines)."""
    lines = (files / "allotta.csv").read_text().splitlines()
    (tmp_path / "bare.csv").write_text("\n".join(line for line in lines if not line.startswith("#")) + "\n")
    _, js = diagnose_json(tmp_path, files / "rec.csv", "--simulation", tmp_path / "bare.csv", "--quiet")
    assert sorted(m["mechanism"] for m in js["missing_physics"]) == ["chip_clogging", "feed_pulsation"]


def test_simulation_on_its_own_clock_is_placed_by_correlation(files, tmp_path):
    """An FE history starts at contact (t = 0); the recording's contact is 2 s in."""
    from femstudy.recordings import read_recording

    sim = read_recording(files / "allotta.csv")
    write_recording(tmp_path / "from_contact.csv", replace(sim, time_s=sim.time_s - 2.0))
    _, js = diagnose_json(tmp_path, files / "rec.csv", "--simulation", tmp_path / "from_contact.csv", "--quiet")
    assert sorted(m["mechanism"] for m in js["missing_physics"]) == ["chip_clogging", "feed_pulsation"]
    (note,) = [n for n in js["notes"] if "runs on another clock" in n]
    assert float(note.split("moved by ")[1].split(" s,")[0]) == pytest.approx(2.0, abs=0.05)  # the alignment refines it


def test_a_cut_ending_by_retraction_is_diagnosed_with_the_cortex_from_the_simulation(tmp_path):
    """No cortex in the header and no --cortex-mm: a cut that stops inside the cortex (retraction,
    no breakthrough) used to be refused; the simulation fixes the timing, and the cortex is taken
    as the depth the simulation reaches, with a note."""
    effects = Effects(**NUISANCE, pulsation=None)
    rec = synthesize(1.5, 1500, mu_f=0.07, effects=effects, stop_depth_mm=4.0, seed=11)
    sim = synthesize(1.5, 1500, mu_f=0.07, model="allotta", effects=Effects.none(), stop_depth_mm=4.0,
                     sample_rate_hz=250)
    strip = lambda r: replace(r, metadata={k: v for k, v in r.metadata.items() if k != "cortex_mm"})
    write_recording(tmp_path / "rec.csv", strip(rec))
    write_recording(tmp_path / "sim.csv", strip(sim))
    _, js = diagnose_json(tmp_path, tmp_path / "rec.csv", "--simulation", tmp_path / "sim.csv", "--quiet")
    assert [m["mechanism"] for m in js["missing_physics"]] == ["chip_clogging"]
    assert js["timing"]["breakthrough_s"] is None
    # the drill went 4 mm in at 1.5 mm/s from contact at 2 s
    assert js["timing"]["cortex_mm"] == pytest.approx(4.0, abs=0.1)
    assert js["timing"]["contact_s"] == pytest.approx(2.0, abs=0.02)
    assert any("does not break through" in n for n in js["notes"])
