"""A parameter sweep over two femurs: the built-in one and a shorter, slimmer one generated
from anatomical parameters, each drilled at mid-diaphysis.

    python docs/examples/sweep_two_femurs.py [OUT_DIR]

The sweep file names the case and the swept key (``geometry.surface``); femstudy runs the
study at every point and tabulates the headline numbers.
"""

import sys
from pathlib import Path

import femstudy

CASE = """
name = "two-femurs"
[mesh]
size_mm = {size}
[analysis]
resolved = false
sensitivity = false   # the sweep itself compares the two femurs; no modelling-choice table per point
[loads]
verify = false        # nor the near-hole verification per point (coarser local models, replicate
                      # placements): a single study of the femur chosen verifies its own measures
[output]
fields = false
figures = false
screenshot = false
"""

SWEEP = """
case = "case.toml"
name = "two-femurs"
[grid]
"geometry.surface" = ["builtin", "small_femur.stl"]
"""


def main(out_dir: Path, mesh_size_mm: float = 8.0, cache_dir: Path = Path(".femstudy-cache")):
    out_dir.mkdir(parents=True, exist_ok=True)
    femstudy.write_femur(out_dir / "small_femur.stl", femstudy.FemurParameters(
        length_mm=400.0, head_diameter_mm=40.0, shaft_diameter_mm=25.0, offset_mm=37.0))
    (out_dir / "case.toml").write_text(CASE.format(size=mesh_size_mm))
    (out_dir / "sweep.toml").write_text(SWEEP)
    result = femstudy.sweep(out_dir / "sweep.toml", out=out_dir / "sweep", cache_dir=cache_dir)
    for row in result.rows:
        print(f"{row['geometry.surface']:>16}: max deflection {row['max_deflection_mm_dynamic']:.4g} mm, "
              f"{row['dofs']:,} DOFs")
    return result


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("results/example-two-femurs"))
