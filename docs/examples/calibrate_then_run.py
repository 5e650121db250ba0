"""Calibrate a bone set on recordings, then run a study with it.

    python docs/examples/calibrate_then_run.py [OUT_DIR]

The recordings here are synthetic (femstudy's generator); put your own in their place. The
calibrated set is saved in a bone library folder and a case names it by ``drilling.bone``.
"""

import sys
from pathlib import Path

import femstudy

REPO = Path(__file__).resolve().parents[2]


def main(out_dir: Path, mesh_size_mm: float = 8.0, cache_dir: Path = Path(".femstudy-cache"), replicates: int = 10):
    data = out_dir / "recordings"
    print(femstudy.write_dataset(data, replicates=replicates, outliers=0, seed=4))
    bones = out_dir / "bones"
    calibration = femstudy.calibrate([data / "calibration"], [data / "validation"], name="examplebone",
                                     out=out_dir / "calibration", neurons=False, figures=False, bones_dir=bones)
    for row in calibration.table():
        print(f"f = {row['feed_mm_s']:g} mm/s, N = {row['spindle_rpm']:g} rpm: "
              f"mu_f = {row['mu_f']:.4f}, mu_w = {row['mu_w']:.4f} ({row['runs']} runs)")
    case = femstudy.load_case(REPO / "cases" / "middiaphysis.toml")
    case = case.model_copy(update={"drilling": case.drilling.model_copy(update={"bone": "examplebone"}),
                                   "analysis": case.analysis.model_copy(update={"resolved": False})})
    result = femstudy.run_study(case, out_dir / "study", mesh_size_mm=mesh_size_mm, cache_dir=cache_dir,
                                bones_dir=bones)
    print(f"with the calibrated friction: mu_f = {result.to_json()['loading']['mu_f']:.4f}, "
          f"max deflection {result.peak('max_deflection_mm').value:.4g} mm")
    return calibration, result


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("results/example-calibration"))
