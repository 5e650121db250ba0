"""`femstudy sweep` on real meshes of the built-in femur (coarse sizes, P1 and a short study)."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import assert_clean_failure, run_cli

CASE = """
name = "sweeptest"
[mesh]
size_mm = 16.0
envelope = 0.002  # the README sweep's envelopes (1e-3 at 8 mm, scaled): its TetWild meshes serve this one
order = 1
[loads]
stations = 1
[time]
end_s = 3.0
step_s = 1.0
[analysis]
resolved = false
[output]
fields = false
screenshot = false
"""


@pytest.fixture(scope="module")
def case_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("sweep-case") / "case.toml"
    path.write_text(CASE)
    return path


def test_mesh_sweep_writes_table_and_convergence_assessment(case_file, shared_cache, tmp_path):
    out = tmp_path / "mesh"
    proc = run_cli("sweep", str(case_file), "--sizes", "32,24,16", "--order", "1", "--out", str(out),
                   env={"FEMSTUDY_CACHE": str(shared_cache)}, timeout=900)
    assert proc.returncode == 0, proc.stderr
    rows = list(csv.DictReader((out / "sweep.csv").open()))
    assert [float(r["size_mm"]) for r in rows] == [32.0, 24.0, 16.0, 24.0, 24.0]  # the middle size remeshed twice
    assert rows[-1]["point"].endswith("(remeshed 2)")
    # the envelope scales with the size, so the meshes refine everywhere together
    assert [float(r["envelope"]) for r in rows[:3]] == pytest.approx([4e-3, 3e-3, 2e-3])
    h = [float(r["h_rep_mm"]) for r in rows[:3]]
    assert h[0] > h[1] > h[2], h
    dofs = [int(r["dofs"]) for r in rows[:3]]
    assert dofs == sorted(dofs), dofs
    assert all(float(r["max_deflection_mm"]) > 0 for r in rows)
    assessment = json.loads((out / "convergence.json").read_text())
    group = assessment["P1-site"]
    quantities = group["quantities"]
    assert {"max_deflection_mm", "max_von_mises_MPa", "max_von_mises_excl_MPa"} <= set(quantities)
    # the remeshing noise is measured (TetWild meshes the same request differently) and used
    twins = [float(rows[k]["max_deflection_mm"]) for k in (1, 3, 4)]
    noise = (max(twins) - min(twins)) / abs(np.mean(twins))
    assert group["remeshing_noise"]["max_deflection_mm"] == pytest.approx(noise, rel=1e-3, abs=1e-5)  # CSV: 6 digits
    assert quantities["max_deflection_mm"]["noise"] == group["remeshing_noise"]["max_deflection_mm"]
    # the peak stress under the patch is singular: never converged; it uses the site size as h
    assert quantities["max_von_mises_MPa"]["verdict"] == "singular"
    assert quantities["max_von_mises_MPa"]["h"][0] == pytest.approx(float(rows[2]["site_size_mm"]))
    # the hole models keep the case's refinement at every size (each run verifies them); the
    # ladder measures the global mesh's effect on them, with the site's element size as h
    assert all(float(r["hole_h_mm"]) == pytest.approx(0.45, rel=1e-5) for r in rows)
    hole = quantities["hole_von_mises_1mm_MPa"]
    assert hole["h"] == pytest.approx(sorted(float(r["site_size_mm"]) for r in rows[:3]), rel=1e-5)
    assert hole["verdict"] != "singular" and all(v > 0 for v in hole["values"])
    text = (out / "sweep.md").read_text()
    assert "GCI" in text and "![" in text
    from PIL import Image

    for figure in Path(out).glob("*.png"):  # drawn plots, not blank canvases
        with Image.open(figure) as image:
            assert len(image.convert("RGB").getcolors(1 << 20)) > 20, figure.name
    # resumed: nothing recomputed, same table
    again = run_cli("sweep", str(case_file), "--sizes", "32,24,16", "--order", "1", "--out", str(out),
                    env={"FEMSTUDY_CACHE": str(shared_cache)})
    assert again.returncode == 0 and "5 of 5 points already finished" in again.stderr, again.stderr
    assert list(csv.DictReader((out / "sweep.csv").open())) == rows


def test_parameter_sweep_is_linear_in_load_and_identical_on_dask(case_file, shared_cache, tmp_path):
    sweep = tmp_path / "scale.toml"
    sweep.write_text(f'case = "{case_file.as_posix()}"\nname = "scale"\n[grid]\n"drilling.load_scale" = [1.0, 2.0]\n')
    env = {"FEMSTUDY_CACHE": str(shared_cache)}
    local = run_cli("sweep", str(sweep), "--out", str(tmp_path / "local"), "--workers", "2", env=env)
    assert local.returncode == 0, local.stderr
    rows = list(csv.DictReader((tmp_path / "local" / "sweep.csv").open()))
    assert [float(r["drilling.load_scale"]) for r in rows] == [1.0, 2.0]
    one, two = (float(r["max_deflection_mm_dynamic"]) for r in rows)
    assert two == pytest.approx(2 * one, rel=2e-6)  # the CSV keeps 6 significant digits
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = run_cli("sweep", str(sweep), "--out", str(tmp_path / "dask"), "--scheduler",
                         cluster.scheduler_address, env=env)
    assert remote.returncode == 0, remote.stderr
    remote_rows = list(csv.DictReader((tmp_path / "dask" / "sweep.csv").open()))
    physics = [k for k in rows[0] if k not in ("total_s",)]
    assert [{k: r[k] for k in physics} for r in remote_rows] == [{k: r[k] for k in physics} for r in rows]


def test_bad_sweep_requests_fail_cleanly(case_file, tmp_path):
    assert_clean_failure(run_cli("sweep", str(case_file)), "needs --sizes")
    assert_clean_failure(run_cli("sweep", str(case_file), "--sizes", "8,-4"),
                         "argument --sizes: -4 mm is out of range: expected more than 0")
    bad = tmp_path / "bad.toml"
    bad.write_text(f'case = "{case_file.as_posix()}"\n[grid]\n"drilling.feed_mm_s" = [1.0, -2.0]\n')
    assert_clean_failure(run_cli("sweep", str(bad)), "feed_mm_s")
