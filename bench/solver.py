"""Cost of the femur FE analyses per linear solver and mesh size.

For each mesh size the femur surface is tetrahedralised with TetWild (cached), marked with
cortical and cancellous regions, clamped 20 mm at both ends and loaded at mid-shaft by the
chip-clogging thrust and torque of the thesis's drilling (2 mm/s, 1500 rpm, 0–3 s in 0.1 s
steps). Every (size, solver) pair runs in a fresh process, so its peak memory is its own:

    assembly   K and M [s]
    static     factorise K_ff + one solve [s]
    transient  30 Newmark steps on the same factorisation (a reduced march in Ritz vectors of
               K_ff, or stepping with K_eff when it does not pass its check) [s], the march and
               how many vectors it used
    peak RSS   of the whole process [GiB]
    ratio      (static + transient) / static: what the transient adds
    f1         lowest natural frequency [Hz] (first solver only)
    u          max deflection [mm], static at the 3 s load and transient peak: equal when
               the 0.1 s steps are quasi-static

Usage (the default surface is the TLEM 2.0 CT femur next to the repository):

    python bench/solver.py                                # 3 sizes × every installed solver
    python bench/solver.py --surface meshes/femur.stl --sizes 8 5 6/1 --solvers pardiso amg

A size "E/R" means TetWild edge length E mm, then R uniform refinements (each splits every
tet in eight): TetWild's time grows steeply below 4 mm (9 min at 3.5 mm here), refinement
reaches 1M DOFs in seconds.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import shlex
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's femstudy, also in the worker processes
DEFAULT_SURFACE = REPO.parent / "shared" / "data" / "femur-tlem2" / "femur_r.stl"
CACHE = REPO / ".femstudy-cache" / "bench-meshes"
CLAMP_MM, CORTEX_MM, DRILL_RADIUS_MM = 20.0, 5.0, 1.35


def tetrahedralise(surface: Path, edge: float, epsilon: float):
    """TetWild's mesh of the surface at target edge length ``edge`` [mm] and envelope
    ``epsilon`` (relative to the bounding-box diagonal), cached."""
    import pytetwild
    import pyvista as pv

    key = hashlib.sha1(f"{surface.resolve()}:{surface.stat().st_size}:{edge}:{epsilon}".encode()).hexdigest()[:12]
    path = CACHE / f"tetwild-{surface.stem}-{edge:g}mm-{key}.npz"
    if not path.exists():
        surf = pv.read(surface).triangulate().clean()
        triangles = int(np.clip(2 * surf.area / (0.433 * edge ** 2), 5000, 40000))
        if triangles < surf.n_cells:  # TetWild's time follows the input's triangle count
            surf = surf.decimate_pro(1 - triangles / surf.n_cells, preserve_topology=True).clean().triangulate()
        start = time.perf_counter()
        with tempfile.TemporaryDirectory() as scratch, contextlib.chdir(scratch):  # fTetWild's debug STLs
            points, tets = pytetwild.tetrahedralize(np.asarray(surf.points, float), surf.faces.reshape(-1, 4)[:, 1:],
                                                    edge_length_abs=edge, epsilon=epsilon)
        print(f"  TetWild {edge:g} mm: {len(tets):,} tets in {time.perf_counter() - start:.0f} s", file=sys.stderr)
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez(path, points=points, tets=tets, surface=np.asarray(surf.points))
    data = np.load(path)
    return data["points"], data["tets"], data["surface"]


def femur_model(surface: Path, size: str, epsilon: float) -> Path:
    """A region-marked tet mesh with clamps and a mid-shaft drill site, as a cached .npz."""
    import skfem
    from scipy.spatial import cKDTree

    edge, _, refine = size.partition("/")
    path = CACHE / f"model-{surface.stem}-{edge}mm-r{refine or 0}-e{epsilon:g}.npz"
    if path.exists() and path.stat().st_mtime > surface.stat().st_mtime:
        return path
    points, tets, surface_points = tetrahedralise(surface, float(edge), epsilon)
    mesh = skfem.MeshTet(np.ascontiguousarray(points.T), np.ascontiguousarray(tets.T, dtype=np.int64))
    for _ in range(int(refine or 0)):
        mesh = mesh.refined()
    points, tets = mesh.p.T, mesh.t.T
    # long axis = direction of largest spread; region by depth below the surface and side
    centred = points - points.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2]
    along = centred @ axes[0]
    centroid = points[tets].mean(axis=1)
    depth = cKDTree(surface_points).query(centroid)[0]
    half = (centroid - points.mean(axis=0)) @ axes[0] > 0
    region = np.where(depth < CORTEX_MM, 1, np.where(half, 2, 3)).astype(np.int8)
    on_surface = np.zeros(len(points), bool)
    on_surface[mesh.facets[:, mesh.boundary_facets()].ravel()] = True
    proximal = on_surface & (along > along.max() - CLAMP_MM)
    distal = on_surface & (along < along.min() + CLAMP_MM)
    # drill site: the surface vertex at mid-length farthest along the second principal axis
    mid = on_surface & (np.abs(along - (along.max() + along.min()) / 2) < 5.0)
    entry = np.flatnonzero(mid)[np.argmax(centred[mid] @ axes[1])]
    normal = axes[1] - (axes[1] @ axes[0]) * axes[0]
    np.savez(path, points=points, tets=tets, region=region, proximal=proximal, distal=distal,
             entry=points[entry], normal=normal / np.linalg.norm(normal))
    return path


def p2_dofs(mesh_path: Path) -> int:
    """3 × (vertices + edges) of a cached mesh."""
    tets = np.load(mesh_path)["tets"]
    pairs = np.sort(tets[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]].reshape(-1, 2), axis=1)
    return 3 * (len(np.unique(tets)) + len(np.unique(pairs[:, 0] * (tets.max() + 1) + pairs[:, 1])))


class PeakMemory:
    """Peak resident set size of this process, sampled every 20 ms."""

    def __init__(self):
        import psutil
        self.process, self.peak, self.running = psutil.Process(), 0, True
        self.thread = threading.Thread(target=self._sample, daemon=True)
        self.thread.start()

    def _sample(self):
        while self.running:
            self.peak = max(self.peak, self.process.memory_info().rss)
            time.sleep(0.02)

    def read(self) -> float:
        self.peak = max(self.peak, self.process.memory_info().rss)
        return self.peak / 2 ** 30


def worker(mesh_path: Path, method: str, steps: int, modes: int) -> dict:
    """One (mesh, solver) measurement, in its own process."""
    from femstudy.drilling.history import DrillingConditions, evaluate
    from femstudy.fe import (assemble, clamp, drill_patch, factorize, solve_modal, solve_static, solve_transient,
                             step_check)
    from femstudy.femur_mesh import Clamps, DrillSite, TetMesh

    memory = PeakMemory()
    data = np.load(mesh_path)
    mesh = TetMesh(data["points"], data["tets"], data["region"])
    start = time.perf_counter()
    system = assemble(mesh)
    out = {"dofs": system.n_dofs, "tets": system.n_tets, "assembly_s": time.perf_counter() - start,
           "assembly_peak_GiB": memory.read()}
    bc = clamp(system, Clamps(data["proximal"], data["distal"]))
    site = DrillSite("mid-shaft", data["entry"], data["normal"], -data["normal"], 6.0)
    patch = drill_patch(system, site, DRILL_RADIUS_MM)
    times = np.round(np.arange(steps + 1) * 0.1, 10)
    loads = evaluate("clogging", DrillingConditions(feed_mm_s=2.0, spindle_rpm=1500.0), times)
    amplitudes = np.column_stack([loads.thrust_N, loads.torque_Nmm])

    start = time.perf_counter()
    fs = factorize(system, bc, method)
    u = solve_static(fs, patch.force(*amplitudes[-1]))
    out["static_s"] = time.perf_counter() - start
    out["solver"], out["static_factor_s"] = fs.method, fs.factor.setup_s
    out["static_max_deflection_mm"] = float(np.linalg.norm(u.reshape(-1, 3), axis=1).max())
    if modes:
        start = time.perf_counter()
        f1 = solve_modal(fs, k=modes).frequency_Hz[0]
        out["modal_s"], out["f1_Hz"] = time.perf_counter() - start, float(f1)
        out["step"] = step_check(1 / f1, 0.1).verdict

    start = time.perf_counter()  # the transient reuses the static factorisation
    march = solve_transient(fs, patch.patterns, amplitudes, times)
    out["transient_s"] = time.perf_counter() - start
    out["transient_scheme"], out["ritz_vectors"] = march.scheme, march.n_vectors
    fields = (march.full_basis() @ march.coordinates).reshape(len(system.nodes), 3, -1)
    out["transient_max_deflection_mm"] = float(np.linalg.norm(fields, axis=1).max())
    out["ratio"] = (out["static_s"] + out["transient_s"]) / out["static_s"]
    out["peak_GiB"] = memory.read()
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--surface", type=Path, default=DEFAULT_SURFACE, help="closed bone surface (STL, mm)")
    parser.add_argument("--sizes", nargs="+", default=["8", "5", "6/1"], help="TetWild edge [mm][/refinements]")
    parser.add_argument("--epsilon", type=float, default=3e-3,
                        help="TetWild envelope; 1e-3 keeps so much surface detail that 8-12 mm give the same mesh")
    parser.add_argument("--solvers", nargs="+", default=None, help="default: every installed solver")
    parser.add_argument("--steps", type=int, default=30, help="Newmark steps of 0.1 s (thesis: 30)")
    parser.add_argument("--modes", type=int, default=1, help="natural frequencies to compute (0: none)")
    parser.add_argument("--timeout", type=float, default=1800, help="seconds per (size, solver) run")
    parser.add_argument("--superlu-max-dofs", type=int, default=300_000, help="skip SuperLU above this")
    parser.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--method", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.worker, args.method, args.steps, args.modes)))
        return 0

    from femstudy.fe import linsolve

    if not args.surface.is_file():
        print(f"bench: no surface at {args.surface}", file=sys.stderr)
        return 2
    solvers = args.solvers or linsolve.available()
    print(f"# python bench/solver.py {' '.join(shlex.quote(a) for a in (argv or sys.argv[1:]))}".rstrip())
    print(f"# surface {os.path.relpath(args.surface, REPO)}, TetWild envelope {args.epsilon:g}; {args.steps} Newmark steps of 0.1 s; "
          "machine: shared, timings noisy")
    header = (f"{'size':>6} {'DOFs':>9} {'solver':>8} {'asm s':>6} {'static s':>8} {'factor s':>8} "
              f"{'march':>10} {'trans. s':>8} {'ratio':>5} {'peak GiB':>8} {'f1 Hz':>7} {'static u':>9} "
              f"{'trans. u':>9}")
    print(header)
    for size in args.sizes:
        print(f"meshing {size} ...", file=sys.stderr)
        mesh_path = femur_model(args.surface, size, args.epsilon)
        for k, method in enumerate(solvers):
            row = {"size": size, "method": method}
            if method == "superlu" and p2_dofs(mesh_path) > args.superlu_max_dofs:
                print(f"{size:>6} {'':>9} {method:>8} skipped: P2 DOFs above --superlu-max-dofs", flush=True)
                continue
            command = [sys.executable, __file__, "--worker", str(mesh_path), "--method", method,
                       "--steps", str(args.steps), "--modes", str(args.modes if k == 0 else 0)]
            try:
                proc = subprocess.run(command, capture_output=True, text=True, timeout=args.timeout)
            except subprocess.TimeoutExpired:
                print(f"{size:>6} {'':>9} {method:>8} timed out after {args.timeout:.0f} s", flush=True)
                continue
            if proc.returncode:
                print(f"{size:>6} {'':>9} {method:>8} failed: {proc.stderr.strip().splitlines()[-1:]}", flush=True)
                continue
            row.update(json.loads(proc.stdout.strip().splitlines()[-1]))
            f1 = f"{row['f1_Hz']:7.0f}" if "f1_Hz" in row else f"{'':>7}"
            print(f"{size:>6} {row['dofs']:>9,} {row['solver']:>8} {row['assembly_s']:6.1f} "
                  f"{row['static_s']:8.1f} {row['static_factor_s']:8.1f} "
                  f"{row['transient_scheme'][:7] + ' ' + str(row['ritz_vectors']):>10} "
                  f"{row['transient_s']:8.1f} {row['ratio']:5.2f} {row['peak_GiB']:8.2f} "
                  f"{f1} {row['static_max_deflection_mm']:9.5f} {row['transient_max_deflection_mm']:9.5f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
