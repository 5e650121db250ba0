"""Femur meshing at three sizes: tets, TetWild time, quality and the cached-rerun time.

For the built-in femur and the TLEM2 CT femur (when ``../shared`` has it), mesh the
mid-diaphysis case (site-refined to 1 mm) at each target edge length in a fresh cache, then
load it again from the cache. Timings are wall-clock on a shared machine: expect noise.

    python bench/mesh.py [--sizes 12 8 5] [--only builtin|tlem2]
"""

from __future__ import annotations

import argparse
import shlex
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TLEM2 = REPO.parent / "shared" / "data" / "femur-tlem2" / "femur_r.stl"


def case_text(surface: str) -> str:
    return f'name = "bench"\n[geometry]\nsurface = "{surface}"\n[site]\nposition = 0.5\ndirection = "anterior"\n'


def main() -> int:
    sys.path.insert(0, str(REPO))
    from femstudy.casefile import parse_case
    from femstudy.study.femur import femur_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[12.0, 8.0, 5.0])
    ap.add_argument("--only", choices=["builtin", "tlem2"])
    args = ap.parse_args()
    femurs = [("builtin", "builtin")]
    if TLEM2.is_file():
        femurs.append(("tlem2", TLEM2.as_posix()))
    else:
        print(f"(TLEM2 femur not found at {TLEM2}; skipped)")
    femurs = [f for f in femurs if args.only in (None, f[0])]
    print("command: python " + " ".join(shlex.quote(a) for a in [str(Path(__file__).relative_to(REPO))] + sys.argv[1:]))
    head = (f"{'femur':<8} {'size_mm':>7} {'tets':>7} {'nodes':>6} {'tetwild_s':>9} {'build_s':>7} "
            f"{'cached_s':>8} {'min_dih_deg':>11} {'rr_min':>6} {'rr_p1':>6} {'rr_p50':>6} {'poor':>4} "
            f"{'site_edge_mm':>12} {'disk_facets':>11} {'cortex_mm':>9} {'vol_err_%':>9}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="femstudy-bench-cache-") as cache:
        for name, surface in femurs:
            case = parse_case(case_text(surface))
            for size in args.sizes:
                start = time.perf_counter()
                cold = femur_model(case, Path(cache), size)
                build_s = time.perf_counter() - start
                start = time.perf_counter()
                warm = femur_model(case, Path(cache), size)
                cached_s = time.perf_counter() - start
                assert warm.stats["cache_hit"] and not cold.stats["cache_hit"]
                s, q = cold.stats, cold.quality
                err = 100 * (s["tet_volume_mm3"] / (s["surface_volume_mm3"] - s["canal_volume_mm3"]) - 1)
                rows.append(f"{name:<8} {size:>7g} {s['n_tets']:>7} {s['n_points']:>6} {s['tetwild_seconds']:>9.1f} "
                            f"{build_s:>7.1f} {cached_s:>8.2f} {q['min_dihedral_deg']:>11.1f} "
                            f"{q['radius_ratio_min']:>6.3f} {q['radius_ratio_percentiles']['1']:>6.3f} "
                            f"{q['radius_ratio_percentiles']['50']:>6.3f} {q['n_poor']:>4} {s['site_edge_mm']:>12.2f} "
                            f"{s['site_facets_in_drill_disk']:>11} {cold.site.cortical_thickness_mm:>9.2f} {err:>+9.2f}")
                print(rows[-1] if len(rows) > 1 else head + "\n" + rows[-1], flush=True)
    print("\ncolumns: tets/nodes of the final mesh; tetwild_s = fTetWild wall time; build_s = whole cold build "
          "(fields, TetWild, classification, site refinement, landmarks); cached_s = the same call served from "
          "the cache; rr = radius ratio 3 r_in/R_circ (p1, p50 percentiles), poor = tets with rr < 0.1; "
          "site_edge_mm = median edge of the outer facets in the drill-radius load disk (disk_facets of them); "
          "cortex_mm = cortex along the drill axis (6 requested); vol_err = tet volume vs surface - canal")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
