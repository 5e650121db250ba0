"""``femstudy diagnose`` on recordings from the independent generator (``bench/independent``,
which shares no trace code with femstudy): decoys whose physics is outside the catalogue are
reported as unexplained and not named as one of the four, coloured noise on a complete case
gives no alarm, and a missing mechanism is named with a held-out R² that improves.

Fixed-seed cases of the benchmark's reporting seed (2); docs/diagnosis.md has the full tables.
"""

import pytest

from bench.independent.cases import CLASSES, make_case
from femstudy.diagnosis.diagnose import diagnose

FOUR = {"chip_clogging", "feed_pulsation", "sensor_drift", "thermal_softening"}


def case_seed(kind: str, i: int = 0) -> int:
    """The benchmark's seed of case ``i`` of ``kind`` at seed 2 (bench/independent/cases.py)."""
    return 200_000 + CLASSES.index(kind) * 1000 + i


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("independent")


def run(kind: str, i: int, folder):
    case = make_case(kind, case_seed(kind, i), folder)
    return case, diagnose(case.recording, case.simulation).to_json()


def overlapping(entries: list[dict], decoy: dict, slack_s: float = 0.5) -> list[dict]:
    return [u for u in entries if u["end_s"] >= decoy["start_s"] - slack_s and u["start_s"] <= decoy["end_s"] + slack_s]


@pytest.mark.slow
@pytest.mark.parametrize("kind, i, shape", [("hard_inclusion", 1, "bump"), ("chip_break_step", 1, "step")])
def test_a_decoy_is_unexplained_and_not_named(kind, i, shape, folder):
    """A 25–50 % harder layer (once named clogging with pulsation) and a chip breaking off."""
    case, js = run(kind, i, folder)
    assert not {m["mechanism"] for m in js["missing_physics"]} & FOUR, js["selection"]
    near = overlapping(js["unexplained"], case.decoy)
    assert any(u["kind"] == shape for u in near), js["unexplained"]
    assert js["residual_check"]["consistent_with_noise"] is False   # and the report does not hide it


@pytest.mark.slow
def test_a_harder_layer_at_the_cortexs_far_side_is_not_named_clogging(folder):
    """Seed 10's first hard inclusion: the lips are still in the layer at breakthrough (3.94 s) and
    leave it at 4.07 s, so its excess falls as the cone clears the cortex, as a chip column's
    does. Without the chisel edge's own column in the layer's form, a clogging stood beside
    the layer with 9/10 of its size and was named (0.80)."""
    case = make_case("hard_inclusion", 1_015_000, folder)
    js = diagnose(case.recording, case.simulation).to_json()
    assert case.decoy["end_s"] > case.events["breakthrough_s"]
    assert not {m["mechanism"] for m in js["missing_physics"]} & FOUR, js["selection"]
    assert any(u["kind"] == "bump" for u in overlapping(js["unexplained"], case.decoy)), js["unexplained"]


def test_a_feed_off_by_twelve_percent_is_not_read_as_two_inverted_channels(folder):
    """feed_or_clock case 1: the recording correlates poorly with the trace at every lag (0.22 at
    its own clock). A mirror placement 15 s later with both channels turned over has the clearer
    weaker edge; placed there, clogging was named. Nothing being clear, the trace's own clock and
    the channels' signs stand."""
    from femstudy.diagnosis import inputs
    from femstudy.recordings import read_recording

    case = make_case("feed_or_clock", case_seed("feed_or_clock", 1), folder)
    rec = read_recording(case.recording)
    sim, correlations = inputs.on_recording_clock(inputs.read_trace(case.simulation, rec), rec)
    assert min(correlations) > 0 and not sim.note


@pytest.mark.slow
def test_complete_simulation_under_ar1_noise_is_silent(folder):
    case, js = run("complete", 1, folder)   # AR(1) amplifier noise, time constant 0.16 s
    assert case.parameters["sensor"]["coloured"] == "ar1"
    assert js["missing_physics"] == [] and js["unexplained"] == [] and js["mismatch"] == []
    assert js["residual_check"]["consistent_with_noise"] is True


@pytest.mark.slow
def test_late_clogging_is_named_and_predicts_held_out_blocks(folder):
    _, js = run("late_clogging", 0, folder)
    assert {m["mechanism"] for m in js["missing_physics"]} == {"chip_clogging"}
    thrust = js["fit"]["channels"]["thrust_N"]
    # a block held out leaves the flexible monotone rise free to take any monotone path through it
    assert thrust["improved"]["r2_heldout"] > 0.95 and thrust["baseline"]["r2_heldout"] < 0.7


@pytest.mark.slow
def test_a_mechanism_a_shape_takes_most_of_is_not_named(tmp_path, monkeypatch):
    """The tuning case behind verdict.BESIDE_SIZE_SHARE (bench/formbench, tuning seed 1): a
    spindle slowing under load. A load shape outside the catalogue beats clogging by ΔBIC 915;
    beside it clogging still lowers the BIC by 59 but keeps 0.19 of its size. Counted as
    standing (no size share), clogging is named; with the share it is not, and the event is
    reported over the decoy's interval. Since layers may end just above the cortex's far face
    (0e84ded) a layer there also takes the clogging's place, so the share is shown without it."""
    from bench.formbench.cases import make_case as make_formbench_case
    from bench.formbench.score import diagnose_case
    from femstudy.diagnosis import verdict
    from femstudy.diagnosis.shapes import SHAPES

    case = make_formbench_case("decoy:spindle_slowdown", 120_003, "tuning", tmp_path)
    truth = tmp_path / f"{case.name}.truth.json"
    kept = diagnose_case(truth)
    assert not set(kept.named) & FOUR and kept.refused is None
    assert overlapping(kept.unexplained, kept.case["decoy"])
    monkeypatch.delitem(SHAPES, "layer")
    assert not set(diagnose_case(truth).named) & FOUR
    monkeypatch.setattr(verdict, "BESIDE_SIZE_SHARE", 0.0)
    assert "chip_clogging" in diagnose_case(truth).named


def test_after_a_replacement_no_subsets_residual_is_scanned_again(tmp_path, monkeypatch):
    """Formbench tuning case softening+pulsation 106002: shapes replace the clogging and the
    softening, and the replacement test runs again on what stands. Every smaller subset it needs
    then was a smaller subset before, so each subset's residual is scanned for competing shapes
    once (the code before scanned them all again)."""
    from bench.formbench.cases import make_case as make_formbench_case
    from bench.formbench.score import diagnose_case
    from femstudy.diagnosis import verdict

    case = make_formbench_case("softening+pulsation", 106_002, "tuning", tmp_path)
    scanned = []
    real = verdict._competitors

    def counted(problem, sent):
        scanned.append(sent[0].subset)
        return real(problem, sent)

    monkeypatch.setattr(verdict, "_competitors", counted)
    outcome = diagnose_case(tmp_path / f"{case.name}.truth.json", workers=1)
    replaced = [m for m, why in outcome.result["selection"]["not_selected"].items()
                if "explains the data better in its place" in why]
    assert replaced and outcome.named
    assert scanned and len(scanned) == len(set(scanned))


def test_the_diagnosis_is_the_same_with_its_fits_and_scans_in_worker_processes_or_not(tmp_path, monkeypatch):
    """The spindle slowdown above goes through every step that runs in worker processes: the
    subsets' fits, the scans of the smaller subsets' residuals for competing shapes, the refits
    with a shape, and the mechanisms refitted beside it. With forking off (everything in the
    caller) the diagnosis's JSON is the same, all but its wall time."""
    from bench.formbench.cases import make_case as make_formbench_case
    from bench.formbench.score import diagnose_case
    from femstudy.diagnosis import fitpool
    from femstudy.lanes import can_fork

    if not can_fork():
        pytest.skip("worker processes are forked on Linux with two or more cores only")
    case = make_formbench_case("decoy:spindle_slowdown", 120_003, "tuning", tmp_path)
    truth = tmp_path / f"{case.name}.truth.json"
    spread = diagnose_case(truth).result
    monkeypatch.setattr(fitpool, "can_fork", lambda: False)
    alone = diagnose_case(truth).result
    assert spread.pop("seconds") > 0 and alone.pop("seconds") > 0
    assert spread == alone


def test_a_shape_scan_smooths_the_load_once_however_many_candidates_return_it(tmp_path, monkeypatch):
    """Every candidate of the timing shape returns the modelled load itself as its second column:
    a scan smooths and whitens it once per channel, not once per candidate (the candidates were
    given a new view of it each, which no two shared)."""
    from bench.formbench.cases import make_case as make_formbench_case
    from bench.formbench.score import diagnose_case
    from femstudy.diagnosis import outside
    from femstudy.diagnosis.shapes import SHAPES

    case = make_formbench_case("clogging", 100_000, "tuning", tmp_path)
    counts = []
    real = outside._distinct_smoothed

    def counted(problem, columns):
        smoothed, positions = real(problem, columns)
        counts.append((len(columns), smoothed.shape[1]))
        return smoothed, positions

    monkeypatch.setattr(outside, "_distinct_smoothed", counted)
    diagnose_case(tmp_path / f"{case.name}.truth.json", workers=1)
    grid = len(SHAPES["timing"].candidates(None))
    timing = [(n, distinct) for n, distinct in counts if n == 2 * grid]
    assert timing and all(distinct == grid + 1 for _, distinct in timing)
