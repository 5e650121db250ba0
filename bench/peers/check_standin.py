"""Agreement of CalculiX and DOLFINx with a plain scikit-fem P2 solution on one clamped tube.

    python bench/peers/check_standin.py [--work results/peers-check]

The stand-in (bench/peers/standin.py) plays femstudy: it assembles the tube, the drill patch
(oblique drill axis, so thrust and torque load the same DOFs) and the clamps, and exports them.

1. static: CalculiX (.dat and .frd) and DOLFINx (MUMPS, CG+GAMG) against scikit-fem;
2. transient, a load ramped over a fraction of the lowest period so that inertia matters:
   CalculiX *DYNAMIC against Newmark average acceleration with the mass matrix integrated
   exactly and with the 4-point rule C3D10 uses; the lowest natural frequencies of both;
3. transient under the case's drilling history (0–3 s, Δt = 0.1 s): the same comparison.

Differences are max |u − u_ref| / max |u_ref| over the whole field (transients: every step).
"""

from __future__ import annotations

import argparse
import dataclasses
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from bench.peers import femstudy_side, standin  # noqa: E402
from bench.peers.case import write_calculix  # noqa: E402
from femstudy.casefile import MaterialsSpec, load_case  # noqa: E402
from femstudy.export.calculix import (StaticStep, read_dat_displacements, read_frd_displacements,  # noqa: E402
                                     run_ccx, write_inp)
from femstudy.study.loading import case_loading  # noqa: E402


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.nanmax(np.abs(a - b)) / np.abs(b).max())


def oblique_tube(**shape):
    mesh, clamps, site = standin.tube_model(**shape)
    direction = np.array([-1.0, 0.3, 0.2]) / np.linalg.norm([-1.0, 0.3, 0.2])
    return mesh, clamps, dataclasses.replace(site, direction=direction)


def newmark_fields(model: femstudy_side.Model, mass_intorder: int | None) -> np.ndarray:
    """Every step's field (steps, 3n) [mm] of the stand-in's Newmark loop."""
    from femstudy.fe import StepRecorder

    system = standin.assemble(model.mesh, model.materials.to_fe(), mass_intorder=mass_intorder)
    patch = standin.drill_patch(system, model.site, radius_mm=model.patch_radius_mm)
    fs = standin.factorize(system, standin.clamp(system, model.clamps))
    steps = tuple(range(1, len(model.times_s)))
    recorder = StepRecorder([], len(model.times_s), keep=steps)
    standin.solve_transient(fs, patch.patterns, np.column_stack([model.thrust_N, model.torque_Nmm]), model.times_s,
                            observer=recorder)
    return np.array([recorder.fields[k] for k in steps])


def static_check(work: Path, materials: MaterialsSpec) -> None:
    mesh, clamps, site = oblique_tube(n_radial=2, n_around=16, n_along=20)
    model = femstudy_side.Model(mesh, clamps, site, materials, np.array([0.0, 1.0]), np.zeros(2), np.zeros(2),
                                80.0, 150.0, patch_radius_mm=8.0)
    peer = femstudy_side.build_peer_case(standin, model)
    peer.save(work / "case.npz")
    u = femstudy_side.solve(standin, model, "static")
    print(f"1. static, tube {peer.n_dofs} DOFs, F = 80 N, T = 150 N·mm, max |u| = "
          f"{np.linalg.norm(u.reshape(-1, 3), axis=1).max():.6g} mm")
    write_inp(work / "static.inp", peer.nodes, peer.elements, peer.region, peer.materials(), peer.fixed_nodes,
              [StaticStep(peer.static_force)], frd=True)
    t0 = time.perf_counter()
    run_ccx(work / "static.inp")
    seconds = time.perf_counter() - t0
    dat = read_dat_displacements(work / "static.dat").dof_vector(0, len(peer.nodes))
    frd = read_frd_displacements(work / "static.frd").dof_vector(0, len(peer.nodes))
    print(f"   CalculiX *STATIC ({seconds:.1f} s): .dat {relative(dat, u):.1e}, .frd {relative(frd, u):.1e}")
    for solver in ("mumps", "gamg"):
        proc = subprocess.run(["/usr/bin/python3", str(REPO / "bench/peers/dolfinx_static.py"), "case.npz",
                               f"dolfinx-{solver}.npz", "--solver", solver], cwd=work, capture_output=True, text=True)
        if proc.returncode:
            raise SystemExit(proc.stderr[-2000:])
        with np.load(work / f"dolfinx-{solver}.npz") as d:
            print(f"   DOLFINx {solver} ({int(d['iterations'])} iterations): {relative(d['u'], u):.1e}")


def transient_check(work: Path, title: str, model: femstudy_side.Model) -> None:
    exact = newmark_fields(model, None)
    four_point = newmark_fields(model, 2)
    peer = femstudy_side.build_peer_case(standin, model)
    write_calculix(peer, work / "transient.inp", "transient")
    t0 = time.perf_counter()
    run_ccx(work / "transient.inp")
    seconds = time.perf_counter() - t0
    h = read_dat_displacements(work / "transient.dat")
    ccx = np.array([h.dof_vector(k, len(peer.nodes)) for k in range(len(h.times_s))])
    watch = ~np.isnan(ccx[0])
    print(f"{title}: tube {peer.n_dofs} DOFs, {len(h.times_s)} steps of {peer.dt_s:.3g} s, "
          f"CalculiX *DYNAMIC {seconds:.1f} s")
    print(f"   CalculiX vs Newmark, exact mass:         {relative(ccx[:, watch], exact[:, watch]):.1e}")
    print(f"   CalculiX vs Newmark, 4-point-rule mass:  {relative(ccx[:, watch], four_point[:, watch]):.1e}")
    print(f"   exact vs 4-point-rule mass (Newmark):    {relative(four_point, exact):.1e}")


def frequencies(model: femstudy_side.Model) -> None:
    found = {}
    for intorder in (None, 2):
        system = standin.assemble(model.mesh, model.materials.to_fe(), mass_intorder=intorder)
        free = standin.clamp(system, model.clamps).free
        lam = spla.eigsh(system.K[free][:, free], k=4, M=system.M[free][:, free], sigma=0, which="LM")[0]
        found[intorder] = np.sqrt(np.sort(lam)) / (2 * np.pi)
    print("   lowest natural frequencies, exact mass: " + ", ".join(f"{f:.2f}" for f in found[None]) + " Hz;"
          " 4-point mass relative shift: " + ", ".join(f"{s:+.1e}" for s in found[2] / found[None] - 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=REPO / "results" / "peers-check")
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    materials = MaterialsSpec()
    static_check(args.work, materials)

    mesh, clamps, site = oblique_tube(n_radial=2, n_around=12, n_along=12)
    t = np.arange(31) * 4e-5           # lowest mode ≈ 650 Hz: period ≈ 38 steps
    fast = femstudy_side.Model(mesh, clamps, site, materials, t, np.interp(t, [0, 3e-4, 1], [0, 80, 80]),
                               np.interp(t, [0, 6e-4, 1], [0, 150, 75]), 80.0, 150.0, patch_radius_mm=10.0)
    transient_check(args.work, "2. transient, ramp over 0.3 ms", fast)
    frequencies(fast)
    loading = case_loading(load_case(REPO / "cases" / "middiaphysis.toml"), site.cortical_thickness_mm)
    slow = dataclasses.replace(fast, times_s=loading.times_s, thrust_N=loading.dynamic.thrust_N,
                               torque_Nmm=loading.dynamic.torque_Nmm)
    transient_check(args.work, "3. transient, drilling history of cases/middiaphysis.toml", slow)


if __name__ == "__main__":
    main()
