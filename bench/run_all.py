"""femstudy against CalculiX and DOLFINx on the same meshes, loads and clamps: bench/RESULTS.md.

    python bench/run_all.py [--geometry femur|tube] [--fe femstudy|standin] [--sizes 8,5,3]
                            [--repeats 3] [--work results/bench-peers] [--out bench/RESULTS.md]

For each mesh size (target edge length [mm]) it builds femstudy's model — the femur of
cases/middiaphysis.toml (``femur``) or a clamped hollow tube (``tube``) — with the case's
materials and its dynamic (0–3 s, Δt = 0.1 s) and static Allotta loads, exports femstudy's
assembled discrete problem to the peers, and times, each in its own process and from outside
(whole-process wall time, peak resident memory), round-robin over ``--repeats`` rounds:

  femstudy static and 30-step transient       bench/peers/femstudy_run.py
  CalculiX 2.20 *STATIC and *DYNAMIC          ccx (SPOOLES), decks from femstudy.export.calculix
  DOLFINx 0.5 static, MUMPS and CG+GAMG        bench/peers/dolfinx_static.py (system python3)

and compares displacements with femstudy's (largest nodal difference over the largest
femstudy displacement; transients: drill-point and maximum-deflection histories). The table
quotes medians. Peers come from bench/peers/setup.sh.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import os
import platform
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: The mesh cache this benchmark meshes into (the command line's default or $FEMSTUDY_CACHE).
CACHE_DIR = Path(os.environ.get("FEMSTUDY_CACHE") or REPO / ".femstudy-cache")
sys.path.insert(0, str(REPO))

from bench.peers import femstudy_side, standin  # noqa: E402
from bench.peers.case import PeerCase, write_calculix  # noqa: E402
from bench.peers.measure import Measurement, measure  # noqa: E402
from femstudy.atomic import write_text  # noqa: E402
from femstudy.casefile import Case, load_case  # noqa: E402
from femstudy.export.calculix import read_dat_displacements  # noqa: E402
from femstudy.study.loading import case_loading  # noqa: E402

CASE_FILE = REPO / "cases" / "middiaphysis.toml"
SYSTEM_PYTHON = "/usr/bin/python3"
THREADS = "2"


@dataclass(frozen=True)
class Run:
    """One solver configuration: a label, the analysis, and how to start it in ``folder``."""

    key: str
    label: str
    analysis: str
    argv: tuple[str, ...]
    env: dict = field(default_factory=dict)
    cwd_is_folder: bool = False


def runs(fe: str, with_ccx_dynamic: bool) -> list[Run]:
    femstudy = (sys.executable, str(REPO / "bench/peers/femstudy_run.py"), "model.npz")
    dolfinx = (SYSTEM_PYTHON, str(REPO / "bench/peers/dolfinx_static.py"), "case.npz")
    out = [Run("femstudy-static", f"femstudy ({fe})", "static",
               femstudy + ("femstudy-static.npz", "--analysis", "static", "--fe", fe)),
           Run("femstudy-transient", f"femstudy ({fe})", "transient",
               femstudy + ("femstudy-transient.npz", "--analysis", "transient", "--fe", fe)),
           Run("ccx-static", "CalculiX *STATIC, SPOOLES", "static", ("ccx", "-i", "ccx-static"),
               {"OMP_NUM_THREADS": THREADS}, cwd_is_folder=True),
           Run("dolfinx-mumps", "DOLFINx, MUMPS Cholesky", "static",
               dolfinx + ("dolfinx-mumps.npz", "--solver", "mumps"), {"OPENBLAS_NUM_THREADS": THREADS}),
           Run("dolfinx-gamg", "DOLFINx, CG + GAMG", "static",
               dolfinx + ("dolfinx-gamg.npz", "--solver", "gamg"), {"OPENBLAS_NUM_THREADS": THREADS})]
    if with_ccx_dynamic:
        out.insert(3, Run("ccx-transient", "CalculiX *DYNAMIC α=0, SPOOLES", "transient",
                          ("ccx", "-i", "ccx-transient"), {"OMP_NUM_THREADS": THREADS}, cwd_is_folder=True))
    return out


def build_model(geometry: str, case: Case, size_mm: float) -> femstudy_side.Model:
    """femstudy's inputs at one mesh size: mesh, clamps, site, materials and both loadings."""
    if geometry == "femur":
        from femstudy.study.femur import femur_model
        femur = femur_model(case, CACHE_DIR, size_mm)
        mesh, clamps, site = femur.mesh, femur.clamps, femur.site
        radius = case.drill.diameter_mm / 2
    else:
        mesh, clamps, site = standin.tube_model(
            n_radial=max(2, math.ceil(7.5 / size_mm)), n_around=max(12, math.ceil(2 * math.pi * 14 / size_mm)),
            n_along=math.ceil(200 / size_mm))
        radius = max(case.drill.diameter_mm / 2, size_mm)   # a coarse tube has no facet within the drill radius
    loading = case_loading(case, site.cortical_thickness_mm)
    return femstudy_side.Model(mesh, clamps, site, case.materials, loading.times_s, loading.dynamic.thrust_N,
                               loading.dynamic.torque_Nmm, loading.static_thrust_N, loading.static_torque_Nmm,
                               patch_radius_mm=radius)


def prepare(folder: Path, geometry: str, fe: str, case: Case, size_mm: float) -> PeerCase:
    """Model, peer case and CalculiX decks in ``folder`` (reused when already there)."""
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / "model.npz").exists():
        build_model(geometry, case, size_mm).save(folder / "model.npz")
    if not (folder / "case.npz").exists():
        subprocess.run([sys.executable, str(REPO / "bench/peers/femstudy_run.py"), "model.npz", "case.npz",
                        "--analysis", "export", "--fe", fe], cwd=folder, check=True)
    peer = PeerCase.load(folder / "case.npz")
    for analysis in ("static", "transient"):
        if not (folder / f"ccx-{analysis}.inp").exists():
            write_calculix(peer, folder / f"ccx-{analysis}.inp", analysis)
    return peer


def execute(run: Run, folder: Path, timeout_s: float | None) -> Measurement:
    env = {**os.environ, "PYTHONPATH": str(REPO), **run.env}
    return measure(list(run.argv), folder / f"{run.key}.log", cwd=folder, env=env, timeout_s=timeout_s).check()


@dataclass
class Outcome:
    """What one solver produced: the comparable quantities."""

    max_deflection_mm: float
    u: np.ndarray | None = None            # static field (3n,) or final transient field
    drill_point_mm: np.ndarray | None = None
    max_history_mm: np.ndarray | None = None   # over all nodes (CalculiX: the surface nodes it wrote)
    surface_history_mm: np.ndarray | None = None


def outcome(run: Run, folder: Path, peer: PeerCase) -> Outcome:
    """Read the last output of ``run``."""
    n = len(peer.nodes)
    if run.key.startswith("ccx"):
        h = read_dat_displacements(folder / f"{run.key}.dat")
        magnitude = np.linalg.norm(h.u, axis=2)
        if run.analysis == "static":
            return Outcome(float(magnitude[-1].max()), u=h.dof_vector(len(h.times_s) - 1, n))
        drill = np.concatenate([[0.0], magnitude[:, np.searchsorted(h.nodes, peer.drill_node)]])
        peak = np.concatenate([[0.0], magnitude.max(axis=1)])
        return Outcome(float(peak.max()), u=h.dof_vector(len(h.times_s) - 1, n), drill_point_mm=drill,
                       max_history_mm=peak)
    with np.load(folder / f"{run.key}.npz") as d:
        if run.analysis == "static":
            u = d["u"]
            return Outcome(float(np.linalg.norm(u.reshape(-1, 3), axis=1).max()), u=u)
        return Outcome(float(d["max_deflection_mm"].max()), u=d["u_final"], drill_point_mm=d["drill_point_mm"],
                       max_history_mm=d["max_deflection_mm"], surface_history_mm=d["surface_max_deflection_mm"])


def relative_difference(peer: Outcome, reference: Outcome) -> float:
    """max |u_peer − u_femstudy| / max |u_femstudy| over the nodes both wrote; for transients
    the largest of that for the final field and of the relative differences of the drill-point
    and surface-maximum deflection histories."""
    a, b = peer.u.reshape(-1, 3), reference.u.reshape(-1, 3)
    both = ~np.isnan(a).any(axis=1)
    diffs = [np.abs(a[both] - b[both]).max() / np.abs(b).max()]
    if peer.drill_point_mm is not None:
        for mine, theirs in ((peer.drill_point_mm, reference.drill_point_mm),
                             (peer.max_history_mm, reference.surface_history_mm)):
            diffs.append(np.abs(mine - theirs).max() / np.abs(theirs).max())
    return float(max(diffs))


def versions() -> list[str]:
    import scipy
    import skfem
    lines = [f"- machine: {platform.node()}, {os.cpu_count()} cores, "
             f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GB, {platform.platform()}",
             f"- femstudy side: Python {platform.python_version()}, numpy {np.__version__}, "
             f"scipy {scipy.__version__}, scikit-fem {skfem.__version__}"]
    ccx = shutil.which("ccx")
    if ccx:
        banner = subprocess.run([ccx, "-v"], capture_output=True, text=True).stdout
        lines.append(f"- CalculiX: {' '.join(banner.split())}, SPOOLES, OMP_NUM_THREADS={THREADS}")
    probe = subprocess.run([SYSTEM_PYTHON, "-c", "import dolfinx, petsc4py; print(dolfinx.__version__, "
                            "petsc4py.__version__)"], capture_output=True, text=True)
    if probe.returncode == 0:
        dx, petsc = probe.stdout.split()
        lines.append(f"- DOLFINx {dx}, PETSc {petsc}, MUMPS, OpenBLAS (OPENBLAS_NUM_THREADS={THREADS}), serial")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--geometry", choices=("femur", "tube"), default="femur")
    parser.add_argument("--fe", choices=sorted(femstudy_side.FE_MODULES), default="femstudy")
    parser.add_argument("--sizes", default="8,5,3", help="mesh sizes [mm], comma-separated")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--ccx-dynamic-max-dofs", type=int, default=150_000,
                        help="skip CalculiX *DYNAMIC above this many DOFs (two factorisations per increment)")
    parser.add_argument("--repeat-limit-s", type=float, default=900.0,
                        help="run only once what takes longer than this the first time")
    parser.add_argument("--timeout-s", type=float, default=7200.0, help="per run")
    parser.add_argument("--work", type=Path, default=REPO / "results" / "bench-peers")
    parser.add_argument("--out", type=Path, default=REPO / "bench" / "RESULTS.md")
    parser.add_argument("--skip", default="", help="comma-separated runs to leave out, e.g. dolfinx-gamg,ccx-transient")
    parser.add_argument("--no-warm-up", action="store_true",
                        help="skip the untimed DOLFINx run (its forms are already compiled, e.g. by an earlier size)")
    args = parser.parse_args()
    needed = [femstudy_side.FE_MODULES[args.fe]] + (["femstudy.meshing"] if args.geometry == "femur" else [])
    missing = [name for name in needed if importlib.util.find_spec(name) is None]
    if missing:
        parser.error(f"{', '.join(missing)} not available in this checkout; try --geometry tube --fe standin")
    case = load_case(CASE_FILE)
    sizes = [float(s) for s in args.sizes.split(",")]
    load_before = os.getloadavg()
    started = time.strftime("%Y-%m-%d %H:%M")
    rows = []
    for size in sizes:
        folder = args.work / f"{args.geometry}-{args.fe}-{size:g}mm"
        print(f"[{size:g} mm] preparing {folder}", file=sys.stderr, flush=True)
        peer = prepare(folder, args.geometry, args.fe, case, size)
        plan = [r for r in runs(args.fe, peer.n_dofs <= args.ccx_dynamic_max_dofs)
                if r.key not in args.skip.split(",")]
        if not args.no_warm_up:
            execute(next(r for r in plan if r.key == "dolfinx-mumps"), folder, args.timeout_s)  # JIT, untimed
        times = {run.key: [] for run in plan}
        for repeat in range(args.repeats):
            for run in plan:
                if repeat and times[run.key][0].wall_s > args.repeat_limit_s:
                    continue                     # one run of something this slow says enough
                m = execute(run, folder, args.timeout_s)
                times[run.key].append(m)
                print(f"[{size:g} mm] {peer.n_dofs} DOFs  {run.key:20s} round {repeat + 1}: "
                      f"{m.wall_s:8.2f} s  {m.peak_MB:7.0f} MB", file=sys.stderr, flush=True)
        results = {run.key: outcome(run, folder, peer) for run in plan}
        for run in plan:
            reference_key = f"femstudy-{run.analysis}"
            wall = float(np.median([m.wall_s for m in times[run.key]]))
            ref_wall = float(np.median([m.wall_s for m in times[reference_key]]))
            rows.append(dict(size=size, dofs=peer.n_dofs, run=run, wall=wall, runs=len(times[run.key]),
                             spread=(min(m.wall_s for m in times[run.key]), max(m.wall_s for m in times[run.key])),
                             peak=float(np.median([m.peak_MB for m in times[run.key]])), ratio=wall / ref_wall,
                             deflection=results[run.key].max_deflection_mm,
                             difference=None if run.key == reference_key else
                             relative_difference(results[run.key], results[reference_key])))
    command = shlex.join([Path(sys.executable).name, "bench/run_all.py", *sys.argv[1:]])
    write_text(args.out, report(rows, args, command, started, load_before, os.getloadavg()))
    print(f"wrote {args.out}", file=sys.stderr)


def report(rows: list[dict], args, command: str, started: str, load_before, load_after) -> str:
    lines = ["# femstudy against CalculiX and DOLFINx", "",
             f"Generated by `{command}` ({started}; load average {load_before[0]:.1f} before, "
             f"{load_after[0]:.1f} after — the machine is shared, so times are noisy). "
             f"Geometry `{args.geometry}`, femstudy solver `{args.fe}`, {args.repeats} rounds (a run "
             f"slower than {args.repeat_limit_s:g} s runs once); wall time and peak memory are "
             "whole-process figures measured from outside, medians (range of wall times in brackets). "
             "*Ratio* is the run's wall time over femstudy's for "
             "the same analysis (> 1: femstudy is faster). *Difference* is max |u − u_femstudy| / "
             "max |u_femstudy| (transients: the largest of that for the final field over the surface "
             "nodes CalculiX writes and of the drill-point and surface-maximum deflection histories; "
             "CalculiX's transient max deflection is over those surface nodes too).", ""]
    lines += versions() + [""] + marches(rows, args) + [""]
    lines += ["| mesh size [mm] | DOFs | solver | analysis | wall time [s] | peak memory [MB] | ratio to femstudy "
              "| max deflection [mm] | difference |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        diff = "reference" if r["difference"] is None else f"{r['difference']:.1e}"
        spread = f"({r['spread'][0]:.2f}–{r['spread'][1]:.2f})" if r["runs"] > 1 else "(1 run)"
        lines.append(f"| {r['size']:g} | {r['dofs']:,} | {r['run'].label} | {r['run'].analysis} | "
                     f"{r['wall']:.2f} {spread} | {r['peak']:.0f} | {r['ratio']:.2f} | "
                     f"{r['deflection']:.6g} | {diff} |")
    folders = os.path.relpath(args.work, REPO) + "/<geometry>-<fe>-<size>mm/"
    lines += ["", "## Targets", ""] + targets(rows) + ["", "## Commands", "",
              f"Each run, from its folder under `{folders}`:", ""]
    seen = set()
    for r in rows:
        run = r["run"]
        if run.key not in seen:
            seen.add(run.key)
            env = " ".join(f"{k}={v}" for k, v in run.env.items())
            argv = [os.path.relpath(a, REPO) if a.startswith(str(REPO)) else a for a in run.argv]
            argv = ["python" if a == sys.executable else a for a in argv]  # no machine paths in the report
            lines.append(f"- {run.label}, {run.analysis}: `{(env + ' ') if env else ''}{shlex.join(argv)}`")
    return "\n".join(lines) + "\n"


def marches(rows: list[dict], args) -> list[str]:
    """How femstudy's transient marched at each size (docs/solver.md, "The Krylov march")."""
    out = []
    for size in dict.fromkeys(r["size"] for r in rows):
        result = args.work / f"{args.geometry}-{args.fe}-{size:g}mm" / "femstudy-transient.npz"
        if result.exists():
            with np.load(result) as d:
                scheme = str(d["scheme"]) if "scheme" in d else "stepping"
                vectors = int(d["krylov_vectors"]) if "krylov_vectors" in d else 0
            out.append(f"{size:g} mm: {scheme}" + (f" on {vectors} Krylov vectors" if vectors else ""))
    return ["femstudy's 30-step transient marched by " + "; ".join(out) + "."] if out else []


def targets(rows: list[dict]) -> list[str]:
    """Issue 35's targets per mesh size, from the medians: femstudy's static whole process at
    least 1.3× as fast as DOLFINx + MUMPS in no more memory, and its transient within 1.1× of
    its static."""
    out = []
    for size in dict.fromkeys(r["size"] for r in rows):
        at = {r["run"].key: r for r in rows if r["size"] == size}
        static, checks = at["femstudy-static"], []
        if "dolfinx-mumps" in at:
            mumps = at["dolfinx-mumps"]
            speed, memory = mumps["wall"] / static["wall"], static["peak"] / mumps["peak"]
            checks += [f"speed vs DOLFINx + MUMPS = {speed:.2f}× (target ≥ 1.3: {_met(speed >= 1.3)})",
                       f"peak memory vs DOLFINx = {memory:.2f} (target ≤ 1: {_met(memory <= 1)})"]
        if "femstudy-transient" in at:
            ratio = at["femstudy-transient"]["wall"] / static["wall"]
            checks.append(f"transient / static = {ratio:.2f} (target ≤ 1.1: {_met(ratio <= 1.1)})")
        out.append(f"- {size:g} mm: " + "; ".join(checks))
    return out


def _met(ok: bool) -> str:
    return "met" if ok else "not met"


if __name__ == "__main__":
    main()
