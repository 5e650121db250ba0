"""The scripts in docs/examples run, using only the public API: on coarse meshes, or at the default
case's own settings where the README's main study kept the answers (conftest.AFTER_MAIN_STUDY)."""

import ast
import importlib.util

import pytest

from conftest import AFTER_MAIN_STUDY, REPO

EXAMPLES = REPO / "docs" / "examples"


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.py")), ids=lambda p: p.stem)
def test_examples_import_only_the_public_api(path):
    """``import femstudy`` and attributes of it that the package lists as public, nothing deeper."""
    import femstudy

    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            assert not (node.module or "").startswith("femstudy"), f"{path.name}: from {node.module} import ..."
        if isinstance(node, ast.Import):
            assert all(a.name == "femstudy" or not a.name.startswith("femstudy") for a in node.names)
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "femstudy":
            assert node.attr in femstudy.__all__, f"{path.name}: femstudy.{node.attr} is not public"


@pytest.mark.slow(rank=AFTER_MAIN_STUDY)
def test_study_example(tmp_path, shared_cache, capsys):
    """At the case's own size: the README's main study, run before it, kept the answers."""
    result = load("study").main(tmp_path / "study", cache_dir=shared_cache)
    assert (tmp_path / "study" / "summary.json").is_file()
    assert result.peak("max_deflection_mm").value > result.peak("max_deflection_mm", "static").value > 0
    assert "dynamic amplification" in capsys.readouterr().out


@pytest.mark.slow
def test_sweep_over_two_femurs_example(tmp_path, shared_cache):
    result = load("sweep_two_femurs").main(tmp_path, mesh_size_mm=16.0, cache_dir=shared_cache)
    small, builtin = (next(r for r in result.rows if r["geometry.surface"] == s) for s in ("small_femur.stl", "builtin"))
    # a shorter, slimmer femur under the same loads: a different model and a different deflection
    assert small["dofs"] != builtin["dofs"] and small["max_deflection_mm_dynamic"] != builtin["max_deflection_mm_dynamic"]
    assert (tmp_path / "sweep" / "sweep.md").is_file()


@pytest.mark.slow
def test_calibrate_then_run_example(tmp_path, shared_cache):
    calibration, result = load("calibrate_then_run").main(tmp_path, mesh_size_mm=16.0, cache_dir=shared_cache,
                                                          replicates=4)
    assert (tmp_path / "bones" / "examplebone.toml").is_file()
    assert result.to_json()["loading"]["bone_set"] == "examplebone"
    mu_f = calibration.bone.friction(2.0, 1500.0)[0]
    assert result.to_json()["loading"]["mu_f"] == pytest.approx(mu_f, rel=1e-12)


def test_diagnose_recording_example(tmp_path, capsys):
    """A recording with clogging, feed pulsation and drift against a clean Allotta trace: the
    example names clogging and pulsation, nothing the recording does not hold, and writes the
    JSON contract. The drift (0.05 N/s, 0.45 N over the record against a 0.3 N noise) stays
    below what the diagnosis names (drop-one ΔBIC 4.5; docs/diagnosis.md, limits)."""
    import dataclasses
    import json

    import femstudy
    from femstudy.recordings import Effects, synthesize, write_recording

    write_recording(tmp_path / "rec.csv", synthesize(1.5, 1500, seed=3))
    write_recording(tmp_path / "sim.csv", synthesize(1.5, 1500, model="allotta", effects=Effects.none(),
                                                     sample_rate_hz=250))
    d = load("diagnose_recording").main(tmp_path / "rec.csv", tmp_path / "sim.csv", tmp_path / "d.json")
    assert isinstance(d, femstudy.Diagnosis)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.seconds = 0.0
    named = {m.mechanism for m in d.mechanisms}
    assert {"chip_clogging", "feed_pulsation"} <= named <= {"chip_clogging", "feed_pulsation", "sensor_drift"}
    js = json.loads((tmp_path / "d.json").read_text())
    assert js["fit"]["improved"]["r2_heldout"] > js["fit"]["baseline"]["r2_heldout"]
    assert "held out" in capsys.readouterr().out
