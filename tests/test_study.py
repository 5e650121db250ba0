"""The study end to end (`femstudy run`) on the built-in femur at a coarse size."""

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import REPO, run_cli
from femstudy.casefile import parse_case
from femstudy.study.run import run_study

CASE = """
name = "e2e"
[mesh]
size_mm = 16.0
order = {order}
[drilling]
load_scale = {scale}
[loads]
application = "{application}"
stations = 1
refinement = 0.5
distances_mm = [1.0, 2.0]
exclusion_radii_mm = [1.0, 2.0]
[time]
end_s = 3.0
step_s = {step}
[analysis]
modes = 2
resolved = {resolved}
sensitivity = {sensitivity}
[output]
fields = {fields}
fields_every = 2
screenshot = {screenshot}
"""


def run(tmp_path, mesh_cache, order=2, scale=1.0, step=0.5, screenshot="true", name="run", fields="true",
        resolved="false", application="surface_patch", keep_solutions=True, parallel=True, sensitivity="false"):
    case = parse_case(CASE.format(order=order, scale=scale, step=step, screenshot=screenshot, fields=fields,
                                  resolved=resolved, application=application, sensitivity=sensitivity))
    out = tmp_path / name
    from femstudy.lanes import Lanes

    result = run_study(case, out, cache_dir=mesh_cache, keep_solutions=keep_solutions,
                       executor=Lanes() if parallel else None)
    return result.to_json(), out


@pytest.fixture(scope="module")
def p2_run(tmp_path_factory, mesh_cache):
    return run(tmp_path_factory.mktemp("study"), mesh_cache, resolved="true", application="hole", sensitivity="true")


def test_results_folder_is_complete(p2_run):
    summary, out = p2_run
    for name in ("summary.json", "timeseries.csv", "report.md", "fields/dynamic.pvd", "fields/static.pvd"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    from PIL import Image

    for name in ("loads.png", "deflection.png", "von_mises.png", "femur.png"):
        with Image.open(out / name) as image:  # a real picture, not an empty canvas
            assert min(image.size) >= 400 and len(image.convert("RGB").getcolors(1 << 20)) > 50, name
    assert json.loads((out / "summary.json").read_text())["results"] == json.loads(json.dumps(summary["results"]))
    rows = list(csv.DictReader((out / "timeseries.csv").open()))
    assert set(rows[0]) == {"loading", "time_s", "thrust_N", "torque_Nmm", "max_deflection_mm",
                            "drill_point_deflection_mm", "max_von_mises_MPa", "max_von_mises_excl_MPa"}
    assert {r["loading"] for r in rows} == {"dynamic", "static"} and len(rows) == 2 * 7
    assert "| maximum deflection [mm] |" in (out / "report.md").read_text()


def test_results_are_consistent(p2_run):
    summary, _ = p2_run
    res = summary["results"]
    for quantity in ("max_deflection_mm", "max_von_mises_MPa"):
        assert res[quantity]["dynamic"]["value"] >= res[quantity]["static"]["value"] > 0
    assert res["drill_point_deflection_mm"]["dynamic"]["value"] <= res["max_deflection_mm"]["dynamic"]["value"]
    assert res["max_von_mises_excl_MPa"]["dynamic"]["value"] <= res["max_von_mises_MPa"]["dynamic"]["value"]
    # the drilling load peaks at breakthrough (3 s) and the response is quasi-static
    assert res["max_deflection_mm"]["dynamic"]["time_s"] == pytest.approx(3.0)
    dynamics = summary["dynamics"]
    assert dynamics["step_check"]["verdict"] == "quasi-static"
    assert dynamics["scheme"] == "reduced" and dynamics["indicator"] < 1e-9
    assert summary["solver"]["factorisations"] in (0, 1)  # 0 when an earlier test kept this K_ff's solutions
    # the resolved run: 50 Hz flute passing against a ~550 Hz lowest mode amplifies by ~(50/550)²
    assert dynamics["resolved_step_s"] == pytest.approx(1 / dynamics["frequencies_Hz"][0] / 20)
    assert dynamics["resolved_indicator"] < 1e-4
    assert 1.0 <= dynamics["dynamic_amplification"] < 1.03
    # the deflection ratio follows the load ratio (thrust dominates the bending)
    load = summary["loading"]
    assert res["max_deflection_mm"]["ratio_dynamic_to_static"] == pytest.approx(
        load["peak_thrust_N"] / load["static_thrust_N"], rel=0.1)


def test_hole_stresses_replace_the_patch_peak(p2_run):
    """With loads.application = "hole" the report quotes the stresses near the hole, with their
    distances and exclusion radius, and its margins come from them, not from the patch's peak."""
    summary, out = p2_run
    hole = summary["hole"]
    assert [r["radius_mm"] for r in hole["distance"]] == [1.0, 2.0]
    near, far = (r["dynamic"]["von_mises_MPa"] for r in hole["distance"])
    assert near > far > 0  # the hole's stress concentration decays away from the wall
    for row in hole["distance"] + hole["exclusion"]:
        assert row["ratio_dynamic_to_static"] > 1  # the clogging loads exceed the static Allotta load
    assert summary["margins"]["basis"] == "hole"
    assert all(m["margin"] > 1 for m in summary["margins"]["dynamic"])
    assert all(m["margin"] == min(m["strength_ratio"], m["strain_ratio"]) for m in summary["margins"]["dynamic"])
    # the drilled depth (the cortex) reaches the canal: the deepest tip stops 0.5 mm short of the
    # local model's own bottom on the axis, so the ligament does not depend on the global mesh
    deepest = hole["stations"][-1]["tip_depth_mm"]
    assert hole["axis_bottom_mm"] - deepest == pytest.approx(hole["options"]["ligament_mm"], abs=1e-12)
    text = (out / "report.md").read_text()
    assert "maximum von Mises stress [MPa]" not in text and "safety factor" not in text


def test_every_near_hole_measure_carries_a_verdict_measured_in_the_run(p2_run):
    """Three refinements of the hole models and replicate placements judge every measure; the
    governing margin is the smallest of all, quoted with its verdict and band."""
    summary, out = p2_run
    verification = summary["hole"]["verification"]
    assert len(verification["levels"]) == 3 and len(verification["replicates_deg"]) >= 3
    measures = verification["measures"]
    kinds = {(m["kind"], m["radius_mm"]) for m in measures}
    assert kinds == {("distance", 1.0), ("distance", 2.0), ("wall", 1.0), ("wall", 2.0), ("exclusion", 1.0),
                     ("exclusion", 2.0)}
    assert all(m["verdict"] in ("converged", "converging", "not converging", "not assessed") for m in measures)
    rows = summary["margins"]["dynamic"]
    governing = summary["margins"]["governing_dynamic"]
    assert governing["margin"] == min(r["margin"] for r in rows)
    assert governing["status"] in ("converged", "band", "not established") and governing["convergence"] is not None
    text = (out / "report.md").read_text()
    assert "Verification in this run" in text and "Governing margin (dynamic loading)" in text
    if governing["status"] != "converged":
        assert f"band {governing['band'][0]:.3g}–{governing['band'][1]:.3g}" in text


def test_fields_are_readable_time_series(p2_run):
    import pyvista as pv

    _, out = p2_run
    reader = pv.get_reader(str(out / "fields" / "dynamic.pvd"))
    assert list(reader.time_values) == pytest.approx([0, 1.0, 2.0, 3.0])
    reader.set_active_time_value(3.0)
    grid = reader.read()[0]
    u = np.linalg.norm(grid.point_data["displacement_mm"], axis=1)
    summary, _ = p2_run
    assert u.max() == pytest.approx(summary["results"]["max_deflection_mm"]["dynamic"]["value"], rel=1e-6)
    assert set(np.unique(grid.cell_data["region"])) == {1, 2, 3}


def test_zero_load_gives_zero_response(tmp_path, mesh_cache):
    summary, _ = run(tmp_path, mesh_cache, order=1, scale=0.0, step=1.0, screenshot="false")
    for quantity in ("max_deflection_mm", "max_von_mises_MPa"):
        assert summary["results"][quantity]["dynamic"]["value"] == 0.0
        assert summary["results"][quantity]["static"]["value"] == 0.0


def test_doubling_the_loads_doubles_the_response(tmp_path, mesh_cache):
    one, _ = run(tmp_path, mesh_cache, order=1, scale=1.0, step=1.0, screenshot="false", name="one")
    two, _ = run(tmp_path, mesh_cache, order=1, scale=2.0, step=1.0, screenshot="false", name="two")
    for quantity in ("max_deflection_mm", "drill_point_deflection_mm", "max_von_mises_MPa"):
        for loading in ("dynamic", "static"):
            assert two["results"][quantity][loading]["value"] == pytest.approx(
                2 * one["results"][quantity][loading]["value"], rel=1e-9)


def test_a_repeated_study_factorises_nothing_and_gives_the_same_maxima(tmp_path, mesh_cache):
    """Kept solutions (femstudy.fe.kept): a study with new load amplitudes on a model solved
    before is served without a factorisation, global or local, and with the modes kept, and its
    maxima, frequencies, resolved peak and hole stresses are those of a study that factorises
    (here twice the loads: exactly twice the response). The study that factorises runs in one
    process, the others in lanes (femstudy.lanes) where they fork: the same numbers either way."""
    from femstudy.lanes import can_fork

    shutil.rmtree(mesh_cache / "solutions", ignore_errors=True)
    shutil.rmtree(mesh_cache / "answers", ignore_errors=True)
    common = dict(order=2, step=0.5, screenshot="false", fields="false", resolved="true", application="hole")
    plain, _ = run(tmp_path, mesh_cache, scale=1.0, name="plain", keep_solutions=False, parallel=False, **common)
    first, _ = run(tmp_path, mesh_cache, scale=1.0, name="first", **common)
    again, _ = run(tmp_path, mesh_cache, scale=2.0, name="again", **common)
    # other loads: the kept answers (femstudy.kept_answers) miss, the kept solutions serve
    assert not again["hole"]["verification"]["kept_from_earlier_run"] and not again["dynamics"]["resolved_kept"]
    assert (plain["solver"]["factorisations"], first["solver"]["factorisations"]) == (1, 1)
    assert again["solver"]["factorisations"] == 0 and again["solver"]["solves_from_kept_solutions"] > 0
    # the quoted level, the coarser and finer levels and two more placements of the coarser: one station each
    assert (first["solver"]["hole_factorisations"], again["solver"]["hole_factorisations"]) == (5, 0)
    assert [s["dynamics"]["modes_kept"] for s in (plain, first, again)] == [False, False, True]
    assert [s["timings"]["parallel"] for s in (plain, first, again)] == [False, can_fork(), can_fork()]
    for loading in ("dynamic", "static"):
        assert again["hole"]["headline"][loading]["von_mises_MPa"] == pytest.approx(
            2 * plain["hole"]["headline"][loading]["von_mises_MPa"], rel=1e-9)
    for quantity in ("max_deflection_mm", "drill_point_deflection_mm", "max_von_mises_MPa", "max_von_mises_excl_MPa"):
        for loading in ("dynamic", "static"):
            reference = plain["results"][quantity][loading]["value"]
            assert first["results"][quantity][loading]["value"] == pytest.approx(reference, rel=1e-9)
            assert again["results"][quantity][loading]["value"] == pytest.approx(2 * reference, rel=1e-9)
    assert again["dynamics"]["frequencies_Hz"] == pytest.approx(plain["dynamics"]["frequencies_Hz"], rel=1e-9)
    assert again["dynamics"]["resolved_peak_mm"] == pytest.approx(2 * plain["dynamics"]["resolved_peak_mm"], rel=1e-9)


def test_a_study_repeated_with_the_same_inputs_reads_its_answers_back(tmp_path, mesh_cache):
    """femstudy.kept_answers: the hole models with their verification, the thesis step's march
    and outputs and the resolved run of a study repeated unchanged are read, not computed, and
    say so, with every number the first run's; a changed load (here its scale) changes their key
    and they are computed again."""
    common = dict(order=2, step=0.5, screenshot="false", fields="false", resolved="true", application="hole")
    first, _ = run(tmp_path, mesh_cache, scale=3.0, name="first", **common)
    same, out = run(tmp_path, mesh_cache, scale=3.0, name="same", **common)
    other, _ = run(tmp_path, mesh_cache, scale=3.5, name="other", **common)
    assert (same["hole"]["verification"]["kept_from_earlier_run"], same["dynamics"]["resolved_kept"],
            same["dynamics"]["step_kept"]) == (True, True, True)
    assert not (other["hole"]["verification"]["kept_from_earlier_run"] or other["dynamics"]["resolved_kept"]
                or other["dynamics"]["step_kept"] or first["dynamics"]["step_kept"])
    assert same["results"] == first["results"]  # the thesis step read back: every series and peak the first's
    assert same["solver"]["factorisations"] == 0 and same["timings"]["hole_s"] < first["timings"]["hole_s"]
    assert same["hole"] == {**first["hole"], "verification": {**first["hole"]["verification"],
                                                             "kept_from_earlier_run": True}}
    assert same["margins"] == first["margins"]
    for name in ("resolved_peak_mm", "quasi_static_peak_mm", "resolved_drill_point_mm", "resolved_indicator"):
        assert same["dynamics"][name] == first["dynamics"][name]
    report = (out / "report.md").read_text()
    assert "this run read it, kept from an earlier run" in report and "Verification in this run" not in report
    assert "Verification, made by an earlier run of the same inputs and code" in report


def test_a_kept_assembly_is_the_assembly(tmp_path, mesh_cache):
    """prepare(keep_assembly=True) keeps the assembled model among the answers and reads it back
    unchanged; without it nothing is kept."""
    from femstudy.study.global_model import prepare

    case = parse_case(CASE.format(order=1, scale=1.0, step=1.0, screenshot="false", fields="false",
                                  resolved="false", application="surface_patch", sensitivity="false"))
    cache = tmp_path / "cache"
    shutil.copytree(mesh_cache, cache, ignore=shutil.ignore_patterns("answers", "solutions"))
    fresh = prepare(case, cache).system
    assert not list((cache / "answers").glob("assembly-*.pickle"))
    prepare(case, cache, keep_assembly=True)
    kept = prepare(case, cache, keep_assembly=True).system
    assert len(list((cache / "answers").glob("assembly-*.pickle"))) == 1
    for name in ("data", "indices", "indptr"):
        assert np.array_equal(getattr(kept.K_blocks, name), getattr(fresh.K_blocks, name))
        assert np.array_equal(getattr(kept.M_nodes, name), getattr(fresh.M_nodes, name))
    assert np.array_equal(kept.nodes, fresh.nodes) and np.array_equal(kept.cells, fresh.cells)
    assert kept.timings == {"kept_from_earlier_run": True} and "pattern_s" in fresh.timings


def test_only_the_newest_kept_assemblies_stay(tmp_path):
    from femstudy.kept_answers import prune
    from femstudy.study.global_model import KEPT_ASSEMBLIES

    for age in range(KEPT_ASSEMBLIES + 2):
        path = tmp_path / f"assembly-{age}.pickle"
        path.write_bytes(b"")
        os.utime(path, (1000.0 - age, 1000.0 - age))
    (tmp_path / "hole-models-0.pickle").write_bytes(b"")
    prune(tmp_path, "assembly", KEPT_ASSEMBLIES)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [f"assembly-{age}.pickle" for age in range(KEPT_ASSEMBLIES)] + ["hole-models-0.pickle"])


def test_view_writes_a_screenshot(p2_run, tmp_path):
    _, out = p2_run
    proc = run_cli("view", str(out), "--field", "displacement", "--screenshot", str(tmp_path / "v.png"))
    assert proc.returncode == 0, proc.stderr
    from PIL import Image

    with Image.open(tmp_path / "v.png") as image:
        colours = image.convert("RGB").getcolors(1 << 20)
    # coloured by displacement: the turbo colour map's many shades, not a blank or one-colour canvas
    assert len(colours) > 200


def test_interrupted_run_never_leaves_a_complete_looking_folder(tmp_path, mesh_cache, p2_run):
    """kill -9 at several moments: results/<name> is either absent or complete; the next run
    succeeds and reuses the cached mesh."""
    case = tmp_path / "e2e.toml"
    case.write_text(CASE.format(order=2, scale=1.0, step=0.5, screenshot="true", fields="true", resolved="false",
                                application="surface_patch", sensitivity="false"))
    env = {**os.environ, "FEMSTUDY_CACHE": str(mesh_cache), "MPLBACKEND": "Agg"}
    out = tmp_path / "results" / "e2e"
    for delay in (1.0, 4.0, 8.0):
        proc = subprocess.Popen([sys.executable, "-m", "femstudy", "run", str(case), "--out", str(out), "--quiet"],
                                cwd=tmp_path, env=env, start_new_session=True,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(delay)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        if out.exists():
            assert (out / "summary.json").is_file() and (out / "report.md").is_file()
        visible = [p.name for p in out.parent.iterdir() if not p.name.startswith(".")] if out.parent.exists() else []
        assert visible in ([], ["e2e"])
    done = run_cli("run", str(case), "--out", str(out), cwd=tmp_path, env={"FEMSTUDY_CACHE": str(mesh_cache)})
    assert done.returncode == 0, done.stderr
    assert "loaded cached mesh" in done.stderr
    assert json.loads((out / "summary.json").read_text())["mesh"]["cache_hit"] is True


def test_combined_study_table_compares_only_the_thesis_sites(p2_run, tmp_path):
    from femstudy.study.study import write_study
    from femstudy.thesis import MAX_DEFLECTION_MM

    summary, _ = p2_run
    names = ("mid-diaphysis", "femoral neck", "lateral condyle", "subtrochanteric", "supracondylar")
    sites = []
    for name in names:
        s = json.loads(json.dumps(summary))
        s["site"]["name"] = name
        sites.append(s)
    text = (write_study(tmp_path, sites)).read_text()
    rows = {name: next(line for line in text.splitlines() if line.startswith(f"| {name} |")) for name in names}
    # the thesis drilled near the neck (its "proximal" row) and near the knee ("distal")
    assert f"| {MAX_DEFLECTION_MM['mid-diaphysis'][0]:.4g} |" in rows["mid-diaphysis"]
    assert "| proximal |" in rows["femoral neck"] and f"| {MAX_DEFLECTION_MM['proximal'][0]:.4g} |" in rows["femoral neck"]
    assert "| distal |" in rows["lateral condyle"] and f"| {MAX_DEFLECTION_MM['distal'][1]:.4g} |" in rows["lateral condyle"]
    for own in ("subtrochanteric", "supracondylar"):
        assert "none (not a thesis site)" in rows[own]
        assert f"| {MAX_DEFLECTION_MM['proximal'][0]:.4g} |" not in rows[own]
    assert f"| {summary['loading']['bone_set']} |" in rows["mid-diaphysis"]
    load = summary["loading"]
    assert f"{load['peak_thrust_N'] / load['static_thrust_N']:.2f}x the static Allotta thrust" in text
    assert json.loads((tmp_path / "study.json").read_text())[3]["site"] == "subtrochanteric"


def test_picture_without_fields_and_report_lists_what_exists(tmp_path, mesh_cache):
    _, out = run(tmp_path, mesh_cache, order=1, step=1.0, fields="false")
    assert (out / "femur.png").is_file() and not (out / "fields").exists()
    text = (out / "report.md").read_text()
    assert "femur.png" in text and "Fields for ParaView" not in text


def test_a_study_in_one_process_writes_what_a_study_in_lanes_writes(tmp_path, mesh_cache):
    """The default executor (one process, --serial) and the command line's lanes: the same files
    and the same numbers (to round-off); without a results folder nothing is written and no
    files part starts."""
    from femstudy.lanes import can_fork

    forks = can_fork()
    lanes, out_lanes = run(tmp_path, mesh_cache, order=1, step=1.0, name="lanes")
    serial, out_serial = run(tmp_path, mesh_cache, order=1, step=1.0, name="serial", parallel=False)
    assert (lanes["timings"]["parallel"], serial["timings"]["parallel"]) == (forks, False)

    def files(folder):
        return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))

    assert files(out_lanes) == files(out_serial) and "femur.png" in files(out_lanes)
    assert lanes["figures"] == serial["figures"]
    for quantity, row in serial["results"].items():
        for loading in ("dynamic", "static"):
            assert lanes["results"][quantity][loading]["value"] == pytest.approx(row[loading]["value"], rel=1e-12)
    case = parse_case(CASE.format(order=1, scale=1.0, step=1.0, screenshot="true", fields="true", resolved="false",
                                  application="surface_patch", sensitivity="false"))
    before = set(tmp_path.iterdir())
    result = run_study(case, None, cache_dir=mesh_cache)
    assert result.out_dir is None and result.timings.files_s is None and result.figures is None
    assert set(tmp_path.iterdir()) == before


def test_the_reduced_march_gives_the_maxima_of_plain_stepping(tmp_path, mesh_cache):
    """The default case's loading on a coarse femur: the study's one-factorisation march
    (Ritz vectors of K_ff) and plain stepping with K-hat factorised (how the transient was
    computed before) give the same maxima to 1e-6."""
    from femstudy import fe
    from femstudy.casefile import with_overrides
    from femstudy.study.global_model import prepare
    from femstudy.study.loading import case_loading

    case = with_overrides(parse_case((REPO / "cases" / "middiaphysis.toml").read_text()), {"mesh.size_mm": 16.0})
    model = prepare(case, mesh_cache)
    loading = case_loading(case, model.femur.site.cortical_thickness_mm)
    patch, channels = model.patch, model.channels
    fs = model.factorize()
    amplitudes = np.column_stack([loading.dynamic.thrust_N, loading.dynamic.torque_Nmm])
    peaks = {}
    for scheme in ("auto", "stepping"):
        recorder = fe.StepRecorder(channels, len(loading.times_s))
        march = fe.solve_transient(fs, patch.patterns, amplitudes, loading.times_s, observer=recorder, scheme=scheme)
        assert march.scheme == {"auto": "reduced", "stepping": "stepping"}[scheme]
        history = recorder.history()
        peaks[scheme] = {k: history[k].peak for k in ("deflection", "drill_point", "von_mises", "von_mises/outside")}
    for name, value in peaks["stepping"].items():
        assert peaks["auto"][name] == pytest.approx(value, rel=1e-6), name
