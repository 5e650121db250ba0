"""Hardening by class (issue #34): no silent absurd result, no deleted user file, no traceback,
nothing that hangs. One section per class of failure; each refusal is checked to be one line,
exit status 2, within 10 s, with nothing of the user's deleted. docs/checks.md lists the rules.

Class 3 (never delete what femstudy did not write) is tested on its own in test_atomic.py,
and the corpus of bad files in test_bad_inputs.py.
"""

from __future__ import annotations

import errno
import json
import math
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import REPO
from femstudy.casefile import parse_case
from femstudy.cli import main
from femstudy.errors import UserError

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                       HealthCheck.function_scoped_fixture])
MIDDIAPHYSIS = (REPO / "cases" / "middiaphysis.toml").read_text().replace(
    'convergence = "convergence/middiaphysis-hole.json"', "")


def refused(argv: list[str], capsys, expect: str, limit_s: float = 10.0) -> str:
    """Run the command line in this process: exit status 2, one ``femstudy ... error:`` line
    holding ``expect``, within ``limit_s``; returns the line."""
    start = time.perf_counter()
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exit_:  # argparse's refusal of a command-line syntax error
        code = exit_.code
    elapsed = time.perf_counter() - start
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line and not line.startswith(("[", "femstudy: warning"))]
    assert code == 2, err
    assert len(lines) == 1 and "error: " in lines[0], err
    assert expect in lines[0], lines[0]
    assert elapsed < limit_s, f"refused after {elapsed:.1f} s"
    return lines[0]


@pytest.fixture
def work(tmp_path, monkeypatch, bone_library):
    """A working folder with a user's file in ``mydata/`` and a private mesh cache."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("FEMSTUDY_CACHE", str(tmp_path / ".femstudy-cache"))
    monkeypatch.setenv("FEMSTUDY_LOGS", str(tmp_path / "logs"))
    (tmp_path / "mydata").mkdir()
    (tmp_path / "mydata" / "notes.txt").write_text("precious")
    yield tmp_path
    assert (tmp_path / "mydata" / "notes.txt").read_text() == "precious"


def case_file(folder: Path, name: str, replace: tuple = (), append: str = "") -> Path:
    text = MIDDIAPHYSIS
    for old, new in replace:
        assert old in text, old
        text = text.replace(old, new)
    path = folder / f"{name}.toml"
    path.write_text(text + append)
    return path


# -- class 1: physical plausibility --------------------------------------------------------

def test_an_extrapolated_friction_law_is_refused_before_any_work(work, capsys):
    case = case_file(work, "fast", [("feed_mm_s = 2.0", "feed_mm_s = 3.0")])
    line = refused(["run", case, "--out", work / "out"], capsys, "mu_w = 43.1")
    assert "--force" in line and not (work / "out").exists() and not (work / ".femstudy-cache").exists()


@FAST
@given(feed=st.floats(0.2, 10.0), rpm=st.floats(600.0, 20_000.0), bone=st.sampled_from(["human", "bovine"]))
def test_an_accepted_operating_point_never_extrapolates_friction_far(feed, rpm, bone):
    """Property: whatever the operating point, the gate lets through only friction inside the
    calibration box or within a factor 2 of the calibrated values, and says which when not."""
    from femstudy.drilling import load_bone_set
    from femstudy.study.plausibility import FRICTION_FACTOR, friction_findings

    case = parse_case(f'name = "p"\n[drilling]\nfeed_mm_s = {feed!r}\nspindle_rpm = {rpm!r}\nbone = "{bone}"\n')
    bones = load_bone_set(bone)
    findings = friction_findings(case.drilling, bones)
    mu = bones.friction(feed, rpm)
    inside = bones.in_calibrated_range(feed, rpm)
    within = [min(c) / FRICTION_FACTOR <= m <= max(c) * FRICTION_FACTOR for m, c in zip(mu, (bones.mu_f, bones.mu_w))]
    assert (findings == []) == (inside or all(within))
    for finding in findings:
        assert finding.check == "friction extrapolated" and "\n" not in finding.message


def summary_with(deflection_mm: float, stress_MPa: float) -> dict:
    """The parts of a summary the result gates read, with a given peak deflection and stress."""
    peak = {"value": deflection_mm, "time_s": 3.0, "location_mm": [0.0, 22.0, 228.0]}
    stress = {"value": stress_MPa, "time_s": 3.0, "location_mm": [1.0, 22.0, 228.0]}
    return {"results": {"max_deflection_mm": {"dynamic": peak, "static": {**peak, "value": deflection_mm / 2},
                                              "ratio_dynamic_to_static": 2.0},
                        "max_von_mises_MPa": {"dynamic": stress, "static": stress, "ratio_dynamic_to_static": 1.0}},
            "dynamics": {"resolved_peak_mm": deflection_mm, "dynamic_amplification": 1.0},
            "margins": {"dynamic": [{"kind": "distance", "strength_ratio": 205.0 / max(stress_MPa, 1e-30)}]}}


@FAST
@given(deflection=st.floats(1e-4, 1e15), stress=st.floats(1e-3, 1e16))
def test_results_beyond_the_bone_are_always_found(deflection, stress):
    """Property: a deflection beyond 2 % of the bone or a stress beyond ten times bone's
    strength is found, whatever its size; values within are not."""
    from femstudy.study.plausibility import BONE_STRENGTH_MPA, result_findings

    checks = {f.check for f in result_findings(summary_with(deflection, stress), 455.6)}
    assert ("deflection beyond the bone" in checks) == (deflection > 0.02 * 455.6)
    assert ("stress beyond bone strength" in checks) == (stress > 10 * BONE_STRENGTH_MPA)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_result_that_is_not_a_number_is_found(bad):
    from femstudy.study.plausibility import result_findings

    assert "not a number" in {f.check for f in result_findings(summary_with(bad, 5.0), 455.6)}


def test_results_within_range_pass_and_force_marks_the_rest():
    from femstudy.study.plausibility import enforce, result_findings

    assert result_findings(summary_with(0.035, 47.0), 455.6) == []
    found = result_findings(summary_with(7.4e11, 4.5e12), 455.6)
    with pytest.raises(UserError, match=r"deflection 7.4e\+11 mm .*--force runs it anyway"):
        enforce(found, force=False)
    marked = enforce(found, force=True)
    assert {m["check"] for m in marked} == {"deflection beyond the bone", "stress beyond bone strength"}


def test_a_drilled_depth_beyond_the_bone_is_found(mesh_cache):
    """depth_mm = 100 at mid-diaphysis, where the canal lies behind a 6 mm cortex: the bone
    along the drill axis is measured on the mesh and the depth refused; 6 mm and "cortex" pass."""
    from femstudy.study.femur import femur_model
    from femstudy.study.plausibility import site_findings

    text = 'name = "depth"\n[mesh]\nsize_mm = 16.0\n[drilling]\ndepth_mm = {}\n'
    model = femur_model(parse_case(text.format(6.0)), mesh_cache)
    found = site_findings(parse_case(text.format(100)), model)
    assert [f.check for f in found] == ["depth beyond the bone"]
    assert "drilling.depth_mm = 100 mm" in found[0].message and "deep" in found[0].message
    assert site_findings(parse_case(text.format(6.0)), model) == []
    assert site_findings(parse_case(text.format('"cortex"')), model) == []


def test_a_forced_absurd_study_is_marked_in_summary_and_report(tmp_path, mesh_cache):
    """Bone a thousand times too soft (within the schema's ranges) deflects by metres: the study
    stops with one line; with force it runs and says so in summary.json and report.md."""
    from femstudy.study.run import run_study

    text = ('name = "soft"\n[mesh]\nsize_mm = 16.0\norder = 1\n[materials.cortical]\nyoungs_modulus_GPa = 0.002\n'
            '[materials.cancellous]\nyoungs_modulus_GPa = 0.001\n[loads]\napplication = "surface_patch"\n'
            '[time]\nstep_s = 1.0\n[analysis]\nmodes = 0\nresolved = false\n[output]\nfields = false\n'
            'figures = false\nscreenshot = false\n')
    case = parse_case(text)
    with pytest.raises(UserError, match="beyond 2 % of the"):
        run_study(case, tmp_path / "refused", cache_dir=mesh_cache)
    assert not (tmp_path / "refused").exists()
    result = run_study(case, tmp_path / "forced", cache_dir=mesh_cache, force=True)
    summary = json.loads((tmp_path / "forced" / "summary.json").read_text())
    assert [f["check"] for f in summary["out_of_range"]] == ["deflection beyond the bone"]
    assert list(result.out_of_range) == summary["out_of_range"]
    assert "**OUT OF RANGE.**" in (tmp_path / "forced" / "report.md").read_text()


# -- class 2: inputs validated whole, before work ------------------------------------------

NUMERIC_KEYS = {"drilling": ["feed_mm_s", "spindle_rpm", "depth_mm", "load_scale"],
                "mesh": ["size_mm", "site_size_mm", "site_radius_mm"],
                "materials.cortical": ["youngs_modulus_GPa", "density_kg_m3"],
                "analysis": ["rayleigh_alpha_per_s", "rayleigh_beta_s", "resolved_lead_s"],
                "time": ["end_s", "step_s"], "clamps": ["length_mm"]}
NOT_NUMBERS = ["true", "false", '"2.0"', "nan", "inf", "-inf", "[1.0]", "1e308", "-1e308", "1e-300"]


@FAST
@given(section=st.sampled_from(sorted(NUMERIC_KEYS)), data=st.data(), value=st.sampled_from(NOT_NUMBERS))
def test_a_number_that_is_not_a_finite_number_in_range_is_refused(section, data, value):
    """Property: booleans, text, non-finite and absurd magnitudes never become numbers; the
    message names the key and its line."""
    key = data.draw(st.sampled_from(NUMERIC_KEYS[section]))
    text = f'name = "t"\n[{section}]\n{key} = {value}\n'
    try:
        case = parse_case(text)
    except UserError as exc:
        assert f"<case>:3: {section}.{key}: " in str(exc) or f"<case>:2: {section}: " in str(exc), str(exc)
        assert "\n" not in str(exc)
        return
    accepted = case.model_dump()
    for part in section.split("."):
        accepted = accepted[part]
    # only a vanishing size or damping gets through, and the estimate judges sizes next
    assert (key, value) in {(k, "1e-300") for k in ("load_scale", "rayleigh_alpha_per_s", "rayleigh_beta_s",
                                                    "site_radius_mm", "resolved_lead_s", "size_mm")}, (key, value)
    assert accepted[key] == 1e-300


CLI_REFUSALS = [  # (name, case-file replacements or None, extra arguments, expected text)
    ("feed given as true", [("feed_mm_s = 2.0", "feed_mm_s = true")], [], "drilling.feed_mm_s: Input should be a valid number, got True"),
    ("spindle nearly stopped", [("spindle_rpm = 1500", "spindle_rpm = 1e-9")], [], "drilling.spindle_rpm"),
    ("Young's modulus 1e-300", [("[time]", "[materials.cortical]\nyoungs_modulus_GPa = 1e-300\n[time]")], [],
     "materials.cortical.youngs_modulus_GPa"),
    ("Rayleigh damping inf", [("[time]", "[analysis]\nrayleigh_alpha_per_s = inf\n[time]")], [], "finite number"),
    ("site size 1e-6", [("site_size_mm = 1.0", "site_size_mm = 1e-6")], [], "mesh.site_size_mm"),
    ("site size beyond memory", [("site_size_mm = 1.0", "site_size_mm = 0.05")], [], "refines the drill site beyond"),
    ("NaN drill direction", [('direction = "anterior"', "direction = [nan, 1, 0]")], [], "three finite numbers"),
    ("inf long axis", [('surface = "builtin"', 'surface = "builtin"\nlong_axis = [inf, 0, 1]')], [],
     "geometry.long_axis: Input should be 'auto', or a vector of three finite numbers"),
    ("case named ..", [('name = "middiaphysis"', 'name = ".."')], [], "name may contain only"),
    ("resolved lead of an hour", [("[time]", "[analysis]\nresolved_lead_s = 3600\n[time]")], [],
     "the resolved transient would march"),
    ("mesh size inf", None, ["--mesh-size", "inf"], "expected a finite number"),
    ("mesh size 1e9", None, ["--mesh-size", "1e9"], "out of range"),
]


@pytest.mark.parametrize("name, replace, extra, expect", CLI_REFUSALS, ids=[c[0] for c in CLI_REFUSALS])
def test_a_bad_case_is_refused_in_one_line_before_any_work(work, capsys, name, replace, extra, expect):
    case = case_file(work, "case", replace or ())
    refused(["run", case, "--out", work / "out", *extra], capsys, expect)
    assert not (work / "out").exists() and not (work / ".femstudy-cache").exists()


def test_a_folder_given_as_the_case_file_is_named_a_folder(work, capsys):
    (work / "cases").mkdir()
    case_file(work / "cases", "a")
    refused(["run", work / "cases"], capsys, "is a folder, not a case file (it holds a.toml")


def write_stl(path: Path, announce: int | None = None, scale: float = 1.0, header: bytes = b"femur") -> Path:
    """The bad-input corpus's femur (744 triangles) as a binary STL, its count or size changed."""
    raw = bytearray((REPO / "tests" / "bad_inputs" / "surfaces" / "femur_with_patella.stl").read_bytes())
    raw[:80] = header.ljust(80)
    if scale != 1.0:
        n = struct.unpack("<I", raw[80:84])[0]
        for k in range(n):
            at = 84 + 50 * k
            values = np.frombuffer(bytes(raw[at:at + 48]), "<f4") * np.float32(scale)
            raw[at:at + 48] = values.astype("<f4").tobytes()
    if announce is not None:
        raw[80:84] = struct.pack("<I", announce)
    path.write_bytes(bytes(raw))
    return path


@pytest.mark.parametrize("make, expect", [
    (lambda p: write_stl(p, announce=200_000_000), "the 200,000,000 triangles its binary STL header announces"),
    (lambda p: write_stl(p, announce=200_000_000, header=b"solid femur"), "header announces"),
    (lambda p: write_stl(p, scale=1e30), "no femur is that long"),
], ids=["announces 200M triangles", "binary with a solid header announces 200M", "scaled by 1e30"])
def test_a_lying_or_absurd_surface_is_refused_before_vtk(work, capsys, make, expect):
    make(work / "femur.stl")
    case = case_file(work, "case", [('surface = "builtin"', 'surface = "femur.stl"\nbodies = "largest"')])
    refused(["run", case, "--out", work / "out"], capsys, expect)
    refused(["mesh", case, "--out", work / "out"], capsys, expect)


def test_a_surface_of_twelve_million_triangles_is_refused_by_its_header(work, capsys):
    with open(work / "big.stl", "wb") as f:  # consistent header and size, sparse: no disk used
        f.write(b"big".ljust(80) + struct.pack("<I", 12_000_000))
        f.truncate(84 + 50 * 12_000_000)
    case = case_file(work, "case", [('surface = "builtin"', 'surface = "big.stl"')])
    refused(["run", case, "--out", work / "out"], capsys, "holds 12,000,000 triangles")


def synthetic(path: Path, capsys, *extra: str) -> Path:
    assert main(["synth", "--out", str(path), "--quiet", *extra]) == 0
    capsys.readouterr()
    return path


def test_a_workbook_claiming_a_million_rows_is_read_as_it_is(work, capsys):
    """A sheet whose ``dimension`` claims A1:XFD1048576: openpyxl padded every row to it (8 GB
    for a 1.5 kB file); now the cells themselves are read, in well under a second."""
    import re
    import zipfile

    import openpyxl

    small = synthetic(work / "small.xlsx", capsys, "--approach-s", "0.3")
    claim = b'<dimension ref="A1:XFD1048576"/>'
    with zipfile.ZipFile(small) as src, zipfile.ZipFile(work / "liar.xlsx", "w", zipfile.ZIP_DEFLATED) as out:
        for info in src.infolist():
            data = src.read(info.filename)
            if info.filename.startswith("xl/worksheets/"):
                data = re.sub(rb"<dimension[^>]*/>", b"", data).replace(b"<sheetData", claim + b"<sheetData", 1)
            out.writestr(info, data)
    book = openpyxl.load_workbook(work / "liar.xlsx", read_only=True)
    assert (book.worksheets[0].max_row, book.worksheets[0].max_column) == (1048576, 16384)  # what it claims
    book.close()
    from femstudy.recordings import read_recording

    start = time.perf_counter()
    rec = read_recording(work / "liar.xlsx")
    assert time.perf_counter() - start < 5 and rec.time_s.size == read_recording(small).time_s.size


@pytest.mark.parametrize("variables, expect", [
    ({"thrust_N": "short"}, "its variables differ in length (time_s 3,000, thrust_N 2,995"),
    ({"thrust_N": "complex"}, "variable thrust_N is complex"),
    ({"thrust_N": "matrix"}, "variable thrust_N is a 3000 x 3 matrix"),
])
def test_a_mat_file_names_what_is_wrong_with_its_variables(work, capsys, variables, expect):
    import scipy.io

    t = np.arange(3000) / 1000.0
    thrust = 20.0 * (t > 1) + np.sin(t)
    shapes = {"short": thrust[:-5], "complex": thrust + 1j, "matrix": np.column_stack([thrust] * 3)}
    scipy.io.savemat(work / "rec.mat", {"time_s": t, "thrust_N": shapes[variables["thrust_N"]],
                                        "torque_Nmm": 2 * thrust, "feed_mm_s": 1.5, "spindle_rpm": 1500.0})
    refused(["diagnose", work / "rec.mat", "--model", "allotta"], capsys, expect)


@pytest.mark.parametrize("change, expect", [
    (lambda cols: [cols[0], cols[1], "3.5"], "torque_Nmm is constant (3.5 N·mm), so its sensor recorded nothing"),
    (lambda cols: [cols[0], f"{float(cols[1]) * 1e300!r}", cols[2]], "a drilling recording stays within ±10000 N"),
], ids=["dead torque channel", "thrust times 1e300"])
def test_a_recording_with_a_dead_or_absurd_channel_is_refused(work, capsys, change, expect):
    rec = synthetic(work / "rec.csv", capsys, "--approach-s", "0.5")
    lines = rec.read_text().splitlines()
    first = next(k for k, line in enumerate(lines) if line.startswith("time_s"))
    body = [",".join(change(line.split(","))) for line in lines[first + 1:]]
    rec.write_text("\n".join(lines[: first + 1] + body) + "\n")
    refused(["diagnose", rec, "--model", "allotta", "--json", work / "d.json"], capsys, expect)
    assert not (work / "d.json").exists()


def test_a_diagnosis_that_is_no_result_is_refused(work, capsys):
    """A torque that varies by a nanonewton-millimetre passes the dead-channel check, and its
    fit's R² comes to -1e31: that is refused, not printed as a diagnosis."""
    rec = synthetic(work / "rec.csv", capsys, "--approach-s", "0.5")
    lines = rec.read_text().splitlines()
    first = next(k for k, line in enumerate(lines) if line.startswith("time_s"))
    body = [",".join(line.split(",")[:2] + [f"{3.5 + 1e-9 * (k % 2):.12f}"]) for k, line in enumerate(lines[first + 1:])]
    rec.write_text("\n".join(lines[: first + 1] + body) + "\n")
    refused(["diagnose", rec, "--model", "allotta", "--json", work / "d.json"], capsys, "which is no result",
            limit_s=300)  # judged after the diagnosis
    assert not (work / "d.json").exists()


def test_a_recording_too_long_to_diagnose_is_refused_before_it_is_read(work, capsys):
    """10 million rows: read in 10 s, then the diagnosis ran past 600 s. Its lines are counted
    first (1.1 million here, 14 MB) and it is refused in a second or two."""
    rows = "".join(f"{k / 1e4:.4f},{k % 7},{k % 5}\n" for k in range(110_000))
    with open(work / "long.csv", "w") as f:
        f.write("# feed_mm_s = 1.5\n# spindle_rpm = 1500\ntime_s,thrust_N,torque_Nmm\n" + rows * 10)
    refused(["diagnose", work / "long.csv", "--model", "allotta"], capsys, "holds about 1,100,003 samples")


def test_a_long_text_read_reports_progress_and_stops_at_its_time_limit(work, capsys, monkeypatch, caplog):
    from femstudy.recordings import read_recording
    from femstudy.recordings.formats import text

    import logging

    rec = synthetic(work / "rec.csv", capsys, "--approach-s", "1")
    monkeypatch.setattr(text, "CHUNK_ROWS", 1000)
    records = []
    handler = logging.Handler()
    handler.emit = records.append
    logging.getLogger("femstudy").addHandler(handler)
    try:
        read_recording(rec)
    finally:
        logging.getLogger("femstudy").removeHandler(handler)
    progress = [r.progress for r in records if hasattr(r, "progress")]
    assert len(progress) >= 3 and progress[-1] == ("reading rec.csv", None, None)
    assert progress[-2][1] > 0.95 * progress[-2][2]  # all of it read (the header is not counted)
    monkeypatch.setattr(text, "READ_TIME_LIMIT_S", -1.0)
    with pytest.raises(UserError, match=r"reading recording rec.csv took longer than -1 s"):
        read_recording(rec)


@pytest.mark.parametrize("force, exponent, expect", [
    ("1e308", "0.4", "initial_force_N = 1e+308 is not a drilling force"),
    ("nan", "0.4", "initial_force_N = nan is not a drilling force"),
    ("20", "inf", "growth_exponent_p = inf is not a growth exponent"),
])
def test_a_table_of_trials_with_impossible_values_is_refused(work, capsys, force, exponent, expect):
    """``femstudy normality`` printed mean nan, sd inf at exit 0 for such a table."""
    rows = "".join(f"{20 + k},{0.4 + 0.01 * k}\n" for k in range(5))
    (work / "trials.csv").write_text(f"initial_force_N,growth_exponent_p\n{rows}{force},{exponent}\n")
    refused(["normality", work / "trials.csv"], capsys, expect)


def test_sweeps_are_judged_whole_before_the_first_point(work, capsys):
    case = case_file(work, "case")
    grid = ", ".join(f"{1.8 + k * 1e-4:.4f}" for k in range(1000))
    (work / "huge.toml").write_text(f'case = "case.toml"\n[grid]\n"drilling.feed_mm_s" = [{grid}]\n'
                                    f'"drilling.spindle_rpm" = [{", ".join(str(1000 + k) for k in range(1000))}]\n')
    refused(["sweep", work / "huge.toml"], capsys, "makes 1,000,000 points (1000 x 1000)")
    (work / "one_bad.toml").write_text('case = "case.toml"\n[grid]\n"drilling.feed_mm_s" = [2.0, 3.0]\n')
    line = refused(["sweep", work / "one_bad.toml", "--out", work / "sweep"], capsys,
                   "sweep point drilling.feed_mm_s=3.0: drilling.feed_mm_s = 3 mm/s")
    assert "--force" not in line and not (work / "sweep").exists()
    for sizes in ("8", "8,8,8", "16,8"):
        refused(["sweep", case, "--sizes", sizes], capsys, "needs 3 or more different sizes")
    refused(["sweep", case, "--sizes", "16,12,8", "--scheduler", "not a url"], capsys,
            "is not a Dask scheduler address")


# -- class 3: never delete what femstudy did not write (see also test_atomic.py) -------------

def test_outputs_that_would_delete_the_users_files_are_refused(work, capsys):
    case = case_file(work, "case")
    twin = case_file(work, "twin")
    (work / "report.md").write_text("mine")
    rec = synthetic(work / "rec.csv", capsys, "--approach-s", "0.5")
    (work / "sub").mkdir()
    inside = synthetic(work / "sub" / "rec.csv", capsys, "--approach-s", "0.5")
    for argv, expect in [
        (["run", case, "--out", work / "mydata"], "femstudy did not write it"),
        (["run", case, "--out", ".femstudy-cache"], "it is the mesh cache"),
        (["run", case, "--out", "."], "it is the working folder"),
        (["run", case, "--out", ".."], "it is the working folder or holds it"),
        (["run", case, twin], "two of the cases are named 'middiaphysis'"),
        (["mesh", case, "--out", work / "mydata"], "femstudy did not write it"),
        (["calibrate", rec, "--out", work / "mydata"], "femstudy did not write it"),
        (["diagnose", rec, "--model", "allotta", "--report", work / "report.md"], "it exists and is a file"),
        (["diagnose", rec, "--model", "allotta", "--json", work / "report.md" / "d.json"], "is not a folder"),
        (["diagnose", inside, "--model", "allotta", "--report", work / "sub"], "holds the input"),
        (["synth", "--dataset", "."], "it is the working folder"),
        (["synth", "--dataset", work / "mydata"], "femstudy did not write it"),
    ]:
        refused(argv, capsys, expect)
    assert (work / "report.md").read_text() == "mine" and rec.is_file() and inside.is_file()
    assert sorted(p.name for p in work.iterdir() if not p.name.startswith(".")) == \
        ["bones", "case.toml", "mydata", "rec.csv", "report.md", "sub", "twin.toml"]
    assert sorted(p.name for p in (work / "sub").iterdir()) == ["rec.csv"]


# -- class 4: no traceback reaches a user ---------------------------------------------------

def test_a_bug_is_one_line_naming_the_log_that_holds_its_traceback(work, capsys, monkeypatch):
    from femstudy.commands import loads

    def broken(args):
        return 1 / 0

    monkeypatch.setattr(loads, "run", broken)
    assert main(["loads", "--feed", "1.5", "--rpm", "1500"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("femstudy: internal error: ZeroDivisionError")
    log = Path(err.rsplit("the traceback is in ", 1)[1].rstrip(")"))
    assert log.parent == work / "logs" and "Traceback" in log.read_text() and "1 / 0" in log.read_text()


@pytest.mark.parametrize("failure, expect", [
    (OSError(errno.ENOSPC, "No space left on device", "results/x/summary.json"), "No space left on device; free"),
    (OSError(errno.EROFS, "Read-only file system", "results"), "Read-only file system"),
    (MemoryError("Unable to allocate 2.39 PiB"), "out of memory (Unable to allocate 2.39 PiB)"),
])
def test_a_failure_of_the_machine_is_one_line_with_exit_2(work, capsys, monkeypatch, failure, expect):
    from femstudy.commands import loads

    def fails(args):
        raise failure

    monkeypatch.setattr(loads, "run", fails)
    refused(["loads", "--feed", "1.5", "--rpm", "1500"], capsys, expect)


@FAST
@given(option=st.sampled_from(["--feed", "--rpm", "--cortex-mm", "--diameter-mm", "--point-angle", "--dt",
                               "--wall-mm", "--u1-mpa"]),
       value=st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                       st.sampled_from(["1e308", "-0", "0", "nan", "x", "1e-300", "", "3.0"])))
def test_any_number_on_the_command_line_gives_a_result_or_one_line(option, value):
    """Property: ``femstudy loads`` with any value of a numeric option ends with 0 or 2, never
    an exception or a traceback."""
    import contextlib
    import io

    options = {"--feed": "1.5", "--rpm": "1500", option: value}
    argv = ["loads"] + [part for pair in options.items() for part in pair]
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exit_:  # argparse's own refusal
            code = exit_.code
    assert code in (0, 2), err.getvalue()
    assert "Traceback" not in err.getvalue()
    if code == 2:
        assert len([line for line in err.getvalue().splitlines() if "error" in line]) == 1


def test_load_histories_no_drill_exerts_are_refused(work, capsys):
    """``femstudy loads`` drew the human law's 1.1e15 N at 3 mm/s; now it refuses, and a feed
    of 30 mm per turn before computing anything."""
    refused(["loads", "--feed", "3", "--rpm", "1500", "--bone", "human", "--csv", work / "l.csv"], capsys,
            "the clogging model's thrust reaches 1.1e+15 N")
    refused(["loads", "--feed", "50", "--rpm", "100"], capsys, "advances the drill 30 mm per turn")
    assert not (work / "l.csv").exists()


def test_a_lane_that_dies_is_named_with_its_signal():
    from femstudy.errors import environment_message
    from femstudy.lanes import LaneFailed, Lanes, can_fork

    if not can_fork():
        pytest.skip("lanes do not fork here")
    with Lanes() as lanes:
        # SIGUSR1 stands for an abort in C code (SIGABRT would also dump the child's stack here)
        aborted = lanes.start("figures and fields", lambda: os.kill(os.getpid(), signal.SIGUSR1))
        killed = lanes.start("hole models", lambda: os.kill(os.getpid(), signal.SIGKILL))
        with pytest.raises(LaneFailed, match=r"the figures and fields process ended without a result \(killed by "
                                             r"SIGUSR1\)$") as caught:
            aborted.result()
        assert environment_message(caught.value) is None  # a crash in C code: a bug, logged
        with pytest.raises(LaneFailed, match=r"killed by SIGKILL\); the machine may have run out of memory") as caught:
            killed.result()
        assert "out of memory" in environment_message(caught.value)


def test_a_full_disk_in_a_forked_process_is_one_line(tmp_path):
    """A lane whose write fails (here past a file-size limit; a full disk fails it alike)
    sends the OSError back as itself, and the command line words it in one line, exit 2."""
    script = ("import resource, sys\nfrom femstudy.lanes import Lanes\nfrom femstudy.errors import environment_message\n"
              "def write():\n    resource.setrlimit(resource.RLIMIT_FSIZE, (1000, 1000))\n"
              f"    open({str(tmp_path / 'big.bin')!r}, 'wb').write(b'x' * 100_000)\n"
              "with Lanes() as lanes:\n    lane = lanes.start('figures and fields', write)\n"
              "    try:\n        lane.result()\n    except Exception as exc:\n        print(environment_message(exc))\n")
    from femstudy.lanes import can_fork

    if not can_fork():
        pytest.skip("lanes do not fork here")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.stdout.strip() == "File too large", proc.stdout + proc.stderr


def test_a_refusal_through_a_real_process_has_no_traceback(tmp_path):
    from conftest import run_cli

    proc = run_cli("run", str(tmp_path / "missing.toml"), "--mesh-size", "1e9", cwd=tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.count("\n") == 1 and "out of range" in proc.stderr


# -- class 5: long reads, caches and pickles ------------------------------------------------

NO_PICKLE_FROM_DISK = """
import pickle, sys
reads = []  # pickles loaded from files, and pickle files opened
def guarded_load(file, *args, **kwargs):  # pickle.load reads from a file: from disk
    reads.append(getattr(file, "name", repr(file)))
    raise AssertionError("a pickle was read from disk")
pickle.load = guarded_load
def opened(event, args):  # any file a pickle is kept in, opened by anyone (pint's cache: *.pickle)
    if event == "open" and isinstance(args[0], str) and args[0].endswith((".pickle", ".pkl", ".pck")):
        reads.append(args[0])
sys.addaudithook(opened)
from femstudy.cli import main
code = main(sys.argv[1:])
print("PICKLE-READS", len(reads), reads[:3])
sys.exit(code)
"""


def test_no_pickle_is_read_from_disk_and_a_planted_pint_cache_never_runs(tmp_path):
    """A recording in kN and N·m needs pint's registry: it is built from pint's definitions,
    not from pint's disk cache (shared by every program, and unpickled): a pickle planted
    there never runs, and no pickle is loaded from any file in the whole diagnosis."""
    caches = tmp_path / "cache-home"
    payload = tmp_path / "payload-ran"
    planted = ("import os\nclass Boom:\n    def __reduce__(self):\n"
               f"        return (os.system, ('touch {payload}',))\n")
    for folder in (caches / "pint", caches / "pint" / "pint"):
        folder.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, "-c", planted + "import pickle, sys\n"
                        f"[open(f'{folder}/' + n, 'wb').write(pickle.dumps(Boom())) for n in "
                        "('registry.pickle', 'cache.pickle', 'default_en.txt.pickle')]"], check=True)
    env = {**os.environ, "XDG_CACHE_HOME": str(caches), "MPLBACKEND": "Agg"}
    subprocess.run([sys.executable, "-m", "femstudy", "synth", "--out", str(tmp_path / "rec.csv"), "--force-unit",
                    "kN", "--torque-unit", "N*m", "--quiet"], env=env, check=True, capture_output=True)
    assert "thrust_kN" in (tmp_path / "rec.csv").read_text()  # read through pint's registry
    planted_files = sorted(str(p) for p in caches.rglob("*"))
    for run in range(2):  # a second run would read whatever the first one cached
        proc = subprocess.run([sys.executable, "-c", NO_PICKLE_FROM_DISK, "diagnose", str(tmp_path / "rec.csv"),
                               "--model", "clogging", "--json", str(tmp_path / f"d{run}.json"), "--workers", "1",
                               "--quiet"], env=env, capture_output=True, text=True, timeout=600, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        assert "PICKLE-READS 0 []" in proc.stdout, proc.stdout
        assert json.loads((tmp_path / f"d{run}.json").read_text())["mismatch"]
    assert not payload.exists()
    assert sorted(str(p) for p in caches.rglob("*") if "matplotlib" not in str(p)) == planted_files


def test_a_mesh_cache_entry_holding_a_pickle_is_never_unpickled(tmp_path, caplog):
    from femstudy.meshing import cache

    key = "f" * 64
    arrays = {"points": np.zeros((4, 3)), "tets": np.array([[0, 1, 2, 3]], np.int32)}
    cache.store(key, arrays, {"frame": {"up": [0, 0, 1]}}, root=tmp_path)
    assert cache.load(key, tmp_path) is not None
    import io
    import hashlib

    buf = io.BytesIO()
    np.savez(buf, points=np.array([object()], dtype=object))  # an object array is a pickle
    data = buf.getvalue()
    (tmp_path / key / "mesh.npz").write_bytes(data)
    record = json.loads((tmp_path / key / "meta.json").read_text())
    record["mesh_sha256"] = hashlib.sha256(data).hexdigest()  # even with a matching checksum
    (tmp_path / key / "meta.json").write_text(json.dumps(record))
    with caplog.at_level("WARNING", logger="femstudy"):
        assert cache.load(key, tmp_path) is None
    assert "corrupted" in caplog.text and not (tmp_path / key).exists()


def test_a_tampered_cache_entry_is_detected(tmp_path, caplog):
    """meta.json is checksummed with the mesh: an entry whose frame's anterior axis was negated
    (a study would drill from the posterior side and call it anterior) is reported and removed."""
    from femstudy.meshing import cache

    key = "e" * 64
    frame = {"up": [0.0, 0.0, 1.0], "anterior": [0.0, 1.0, 0.0]}
    cache.store(key, {"points": np.ones((4, 3))}, {"frame": frame}, root=tmp_path)
    meta = tmp_path / key / "meta.json"
    record = json.loads(meta.read_text())
    assert cache.load(key, tmp_path)[1]["frame"] == frame
    record["meta"]["frame"]["anterior"] = [0.0, -1.0, 0.0]
    meta.write_text(json.dumps(record))
    with caplog.at_level("WARNING", logger="femstudy"):
        assert cache.load(key, tmp_path) is None
    assert "meta.json does not match its checksum" in caplog.text and not (tmp_path / key).exists()


CONCURRENT_BUILD = """
import json, os, sys, time
import numpy as np
from femstudy.casefile import parse_case
from femstudy.meshing import model as model_module
from femstudy.study.femur import femur_model

CASE = parse_case('name = "c"\\n[mesh]\\nsize_mm = 16.0\\n')
warm = femur_model(CASE, sys.argv[3])  # the session's cached mesh stands in for TetWild's

def slow_build(spec, path, size):  # a TetWild run: slow, and a different mesh in each process
    with open(sys.argv[2], "a") as log:
        log.write(f"{os.getpid()}\\n")
    time.sleep(2.0)
    noise = 1e-6 * np.random.default_rng(os.getpid()).random(warm.mesh.points.shape)
    arrays = {"points": warm.mesh.points + noise, "tets": warm.mesh.tets.astype(np.int32),
              "region": warm.mesh.region, "canal_axis": warm.canal_axis}
    stats = {k: v for k, v in warm.stats.items() if k not in ("cache_hit", "cache_key")}
    return arrays, {"frame": warm.frame.as_dict(), "quality": warm.quality, "stats": stats}

model_module._build = slow_build
m = femur_model(CASE, sys.argv[1])
print(json.dumps({"key": m.stats["cache_key"], "sum": float(m.mesh.points.sum()), "hit": m.stats["cache_hit"],
                  "frame": m.frame.as_dict()}, default=str))
"""


def test_two_cold_builds_of_one_mesh_at_once_mesh_once_and_agree(tmp_path, mesh_cache):
    """Two processes ask for the same uncached mesh at once: the second waits on the entry's
    lock and loads the first one's mesh (TetWild, not deterministic, runs once), so both
    describe the same mesh under the same key."""
    from femstudy.study.femur import femur_model

    femur_model(parse_case('name = "c"\n[mesh]\nsize_mm = 16.0\n'), mesh_cache)  # warm the stand-in
    builds = tmp_path / "builds.log"
    cmd = [sys.executable, "-c", CONCURRENT_BUILD, str(tmp_path / "cache"), str(builds), str(mesh_cache)]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=900) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-2000:] for o in outs]
    results = [json.loads(o[0].strip().splitlines()[-1]) for o in outs]
    assert len(builds.read_text().split()) == 1, "the mesh was built twice"
    assert results[0]["key"] == results[1]["key"] and results[0]["sum"] == results[1]["sum"]
    assert results[0]["frame"] == results[1]["frame"]
    assert sorted(r["hit"] for r in results) == [False, True]
