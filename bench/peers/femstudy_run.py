"""femstudy solving one benchmark model in its own process (so that it is timed like the peers).

    python bench/peers/femstudy_run.py MODEL.npz OUT.npz --analysis static|transient|export [--fe femstudy|standin]

``static`` writes ``u`` (3n,) [mm]; ``transient`` what :func:`femstudy_side.solve` returns
(per-step deflection histories [mm] and the final field); ``export`` the assembled discrete problem as a peer case
(bench/peers/case.py) for CalculiX and DOLFINx. Phase times [s]: ``t_setup`` (assembly, patch,
clamps) and ``t_solve``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.peers import femstudy_side  # noqa: E402
from femstudy.atomic import atomic_path  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model")
    parser.add_argument("out")
    parser.add_argument("--analysis", choices=("static", "transient", "export"), required=True)
    parser.add_argument("--fe", choices=sorted(femstudy_side.FE_MODULES), default="femstudy")
    args = parser.parse_args()
    fe = femstudy_side.fe_module(args.fe)
    model = femstudy_side.Model.load(args.model)
    if args.analysis == "export":
        femstudy_side.build_peer_case(fe, model).save(args.out)
        return
    t0 = time.perf_counter()
    system, patch, bc = femstudy_side.setup(fe, model)
    t_setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = femstudy_side.solve(fe, model, args.analysis, system, patch, bc)
    t_solve = time.perf_counter() - t0
    arrays = {"u": result} if args.analysis == "static" else result
    with atomic_path(args.out) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, t_setup=t_setup, t_solve=t_solve, n_dofs=system.n_dofs, **arrays)
    march = f", {result['scheme']} march" if args.analysis == "transient" else ""
    print(f"femstudy {args.analysis} ({args.fe}): {system.n_dofs} DOFs, setup {t_setup:.2f} s, "
          f"solve {t_solve:.2f} s{march}")


if __name__ == "__main__":
    main()
