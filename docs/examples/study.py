"""A drilling study from a script: run the mid-diaphysis case, then read its results.

    python docs/examples/study.py [OUT_DIR]

Uses only the public API (``import femstudy``); the tests run it on a coarse mesh.
"""

import sys
from pathlib import Path

import femstudy

REPO = Path(__file__).resolve().parents[2]


def main(out_dir: Path, mesh_size_mm: float = 8.0, cache_dir: Path = Path(".femstudy-cache")):
    case = femstudy.load_case(REPO / "cases" / "middiaphysis.toml")
    result = femstudy.run_study(case, out_dir, mesh_size_mm=mesh_size_mm, cache_dir=cache_dir)
    for quantity in ("max_deflection_mm", "max_von_mises_excl_MPa"):
        dynamic, static = result.peak(quantity), result.peak(quantity, "static")
        print(f"{quantity}: {dynamic.value:.4g} dynamic at t = {dynamic.time_s:.2f} s, {static.value:.4g} static")
    rows = result.timeseries()  # one dict per loading and step, units in the keys
    print(f"{len(rows)} rows, e.g. {rows[-1]}")
    print(f"dynamic amplification from the resolved run: {result.dynamics.amplification:.4f}")
    return result


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("results/example-study"))
