"""``femstudy calibrate`` end to end on a synthetic data set, and its refusals of bad input."""

import csv
import shutil
from dataclasses import replace

import pytest

from conftest import assert_clean_failure, run_cli
from femstudy.cli import main
from femstudy.drilling.friction import load_bone_set
from femstudy.recordings import write_recording
from femstudy.recordings.dataset import Spread, dataset_recordings, random_effects


def rig_without_pulsation(rng):
    return replace(random_effects(rng), pulsation=None)


@pytest.fixture(scope="session")
def small_dataset(tmp_path_factory):
    """Five conditions x 5 replicates (one planted outlier) + 4 validation runs; the replicates
    scatter by 4 % and the rig adds noise, ripple and drift but no feed pulsation."""
    folder = tmp_path_factory.mktemp("dataset")
    for relative, rec in dataset_recordings(replicates=5, outliers=1, seed=3, effects=rig_without_pulsation,
                                            spread=Spread(0.04, 0.04, 0.05, (5.5, 8.0))):
        write_recording(folder / relative, rec)
    return folder


def rows(path):
    return list(csv.DictReader(path.open()))


def test_calibrate_recovers_the_generating_friction_and_saves_a_usable_bone_set(small_dataset, tmp_path, bone_library):
    out = tmp_path / "cal"
    proc = run_cli("calibrate", str(small_dataset / "calibration"), "--validate", str(small_dataset / "validation"),
                   "--name", "testbone", "--out", str(out), env={"FEMSTUDY_BONES": str(bone_library)})
    assert proc.returncode == 0, proc.stderr
    assert (bone_library / "testbone.toml").is_file() and (out / "testbone.toml").is_file()
    for name in ("report.txt", "runs.csv", "conditions.csv", "validation.csv", "ann_neurons.csv", "fits.png",
                 "power_law.png", "validation.png", "normality.png", "ann_neurons.png"):
        assert (out / name).stat().st_size > 0, name
    # friction per condition: against the runs' own true friction (their geometric mean) the
    # error is the estimation error, 0.3 % per run at most here, allow 1 %; against the
    # generating law add the sampling error of 4-5 replicates scattered by 4 % (2 % standard
    # error), allow 10 %
    for c in rows(out / "conditions.csv"):
        for mu in ("mu_f", "mu_w"):
            assert float(c[mu]) == pytest.approx(float(c[f"sample_true_{mu}"]), rel=0.01)
            assert float(c[mu]) == pytest.approx(float(c[f"true_{mu}"]), rel=0.10)
    runs = rows(out / "runs.csv")
    planted = [r for r in runs if r["role"] == "outlier"]
    assert len(planted) == 1 and "robust SDs" in planted[0]["outlier_reason"]
    validation = rows(out / "validation.csv")
    assert len(validation) == 4 and min(float(v["r2_thrust"]) for v in validation) > 0.8
    assert "Tables 4-2/4-3 method" in proc.stdout and "neuron study" in proc.stdout
    # the saved set is what femstudy loads (and a case file's [drilling] bone = "testbone") resolves
    bone = load_bone_set(str(out / "testbone.toml"))
    conditions = {(float(c["feed_mm_s"]), float(c["spindle_rpm"])): c for c in rows(out / "conditions.csv")}
    assert bone.mu_f == pytest.approx(tuple(float(c["mu_f"]) for c in conditions.values()), rel=1e-5)
    loads = run_cli("loads", "--feed", "1.5", "--rpm", "1250", "--bone", "testbone",
                    env={"FEMSTUDY_BONES": str(bone_library)})
    assert loads.returncode == 0, loads.stderr
    assert "bone set 'testbone'" in loads.stdout and "inside its calibrated range" in loads.stdout
    # and a study case naming it takes its friction at a calibrated condition
    from femstudy.casefile import load_case
    from femstudy.study.loading import case_loading

    case_file = tmp_path / "case.toml"
    case_file.write_text('name = "own-bone"\n[drilling]\nbone = "testbone"\nfeed_mm_s = 1.5\nspindle_rpm = 1250\n')
    friction = case_loading(load_case(case_file, bone_library), 6.0, bone_library).conditions.friction
    c = conditions[(1.5, 1250.0)]
    assert friction == pytest.approx((float(c["mu_f"]), float(c["mu_w"])), rel=0.05)


def test_held_out_replicates_when_no_validation_runs_are_given(small_dataset, tmp_path, bone_library, capsys):
    out = tmp_path / "cal"
    assert main(["calibrate", str(small_dataset / "calibration"), "--holdout", "1", "--no-ann", "--no-figures",
                 "--quiet", "--name", "held", "--out", str(out)]) == 0
    validation = rows(out / "validation.csv")
    assert len(validation) == 5 and {v["role"] for v in validation} == {"held out"}
    assert not (out / "fits.png").exists() and (bone_library / "held.toml").is_file()


def _bad_cases(good):
    header = "".join(line for line in good.read_text().splitlines(keepends=True) if line.startswith("#"))
    body = [line for line in good.read_text().splitlines(keepends=True) if not line.startswith("#")]
    return {
        "missing column": (header + body[0].replace("thrust_N", "force_N") + "".join(body[1:]),
                           "has no thrust_N column"),
        "unit-less column": (header + body[0].replace("torque_Nmm", "torque") + "".join(body[1:]),
                             "column 'torque' has no unit"),
        "non-monotonic time": (header + body[0] + body[2] + body[1] + "".join(body[3:]), "time_s goes backwards"),
        "NaN row": (header + "".join(body[:3]) + body[3].split(",")[0] + ",nan,1\n" + "".join(body[4:]),
                    "thrust_N is nan at line"),
        "empty file": ("", "is empty"),
        "absent metadata": (header.replace("# feed_mm_s", "# feed_was") + "".join(body), "has no feed_mm_s"),
        "no torque": (header.replace("# samples", "# samples_was") + "".join(
            ",".join(line.split(",")[:2]) + "\n" for line in body), "has no torque column"),
    }


@pytest.mark.parametrize("case", ["missing column", "unit-less column", "non-monotonic time", "NaN row",
                                  "empty file", "absent metadata", "no torque"])
def test_bad_recordings_give_one_clear_message_exit_2_and_write_nothing(small_dataset, tmp_path, bone_library,
                                                                        capsys, case):
    runs = tmp_path / "runs"
    shutil.copytree(small_dataset / "calibration", runs)
    good = sorted(runs.glob("*.csv"))[3]
    text, message = _bad_cases(good)[case]
    good.write_text(text)
    out = tmp_path / "out"
    assert main(["calibrate", str(runs), "--out", str(out), "--quiet", "--no-ann"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("femstudy: error: ") and message in err and good.name in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists() and not any(bone_library.iterdir())


@pytest.mark.parametrize("args, message", [
    (["--set", "feed_mm_s=3.0"], "says feed_mm_s = 1.5 but the command line says 3.0; remove one of them, "
                                 "or pass --override"),
    (["--name", "bovine"], "is a built-in bone set"),
    (["--name", "../x"], "--name may contain only"),
    (["--set", "nonsense"], "--set expects KEY=VALUE"),
])
def test_bad_options_are_refused_before_any_work(small_dataset, tmp_path, bone_library, capsys, args, message):
    out = tmp_path / "out"
    assert main(["calibrate", str(small_dataset / "calibration"), "--out", str(out), "--quiet", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and not any(bone_library.iterdir())


def test_too_few_conditions_for_the_power_law(small_dataset, tmp_path, bone_library, capsys):
    runs = sorted((small_dataset / "calibration").glob("f1.5_*.csv")) + sorted(
        (small_dataset / "calibration").glob("f1_*.csv"))
    assert main(["calibrate", *map(str, runs), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "needs calibration runs at four or more (feed, speed) conditions; these cover 3" in capsys.readouterr().err


def test_contradicting_metadata_through_the_console_script_has_no_traceback(small_dataset, tmp_path):
    proc = run_cli("calibrate", str(small_dataset / "calibration"), "--set", "spindle_rpm=999",
                   "--out", str(tmp_path / "o"), env={"FEMSTUDY_BONES": str(tmp_path / "bones")})
    assert proc.returncode == 2
    assert_clean_failure(proc, "but the command line says 999")
    assert not (tmp_path / "o").exists() and not (tmp_path / "bones").exists()
