"""Frame detection on femurs in random poses: long axis, proximal end, side, anterior, units.

Each femur is read once, then put in ``--poses`` random poses (a uniformly random rotation,
a translation anywhere in a 2 m cube, mirrored every other pose, units drawn from mm, cm, m
and inches, and quadric decimation removing 0-90 % of its triangles) and its frame detected
again. A pose passes when the units, the side and the proximal end are right, the long
axis is within 10 degrees of the true one and the anterior within 15 degrees.

The truth of each femur in its file's frame: the built-in femur's generator frame (+z
proximal, +y anterior, left); TLEM 2.0's ISB frame (+y proximal, +x anterior, right); for
the other femurs a landmark frame (:func:`landmark_frame`): long axis from the knee centre to
the head centre, anterior perpendicular to the line through the posterior condyles' centres.
The landmarks are found from a coarse orientation read off pictures of each file
(:data:`FURTHER_FEMURS`), independently of the detection.

    python bench/frame_poses.py [--poses 50] [--seed 1] [--femurs DIR] [--only NAME ...]

The further femurs are STL files in ``--femurs`` (default ../femurs from the repository
root; docs/meshing.md says where they come from); missing ones are skipped, saying so.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TLEM2 = REPO.parent / "shared" / "data" / "femur-tlem2" / "femur_r.stl"
UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
LONG_AXIS_TOL_DEG, ANTERIOR_TOL_DEG = 10.0, 15.0

#: name: (proximal, anterior, side) of the file's own frame, read off pictures of it; the
#: condyle offset, the shaft bow and the head's forward angle all agree with it.
FURTHER_FEMURS = {
    "LHDL_CT_femur_r": ((0, 0, 1), (0, -1, 0), "right"),
    "VAKHUM_CT_femur_r": ((0, 0, -1), (0, -1, 0), "right"),
    "TLEM2_CT_femur_l": ((0, 0, 1), (0, -1, 0), "left"),
    "TLEM2_MRI_femur_l": ((0, 0, 1), (0, -1, 0), "left"),
    "TLEM2_MRI_femur_r": ((0, 0, 1), (0, -1, 0), "right"),
    "JIA_MRI_femur_l": ((0, 0, 1), (0, -1, 0), "left"),
    "JIA_MRI_femur_r": ((0, 0, 1), (0, -1, 0), "right"),
    "ICL_MRI_femur_r": ((0, 0, 1), (0, 1, 0), "right"),
}


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _angle(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(_unit(a) @ _unit(b), -1.0, 1.0))))


def _sphere(points):
    """Least-squares sphere |x|² = 2 c·x + k (written out here, apart from the library's)."""
    A = np.column_stack([2 * points, np.ones(len(points))])
    sol, *_ = np.linalg.lstsq(A, (points ** 2).sum(axis=1), rcond=None)
    return sol[:3], float(np.sqrt(sol[3] + sol[:3] @ sol[:3]))


def landmark_frame(points, triangles, up, anterior, side):
    """Reference (up, anterior) from landmarks, given a coarse orientation.

    Head: a sphere through the most medial points of the proximal 15 %, refitted five times
    to the points within 10 % of its radius. Knee: spheres through the posterior halves of
    the medial and lateral condyles (the distal 12 %, facets facing backwards), as STAPLE's
    spheres-on-condyles frame. Up = knee centre -> head centre; anterior = up × (centre of
    the right-hand condyle - the left-hand one), made perpendicular to up.
    """
    up, anterior = _unit(up), _unit(anterior)
    right = np.cross(anterior, up)
    medial = right if side == "left" else -right
    h = points @ up
    length = np.ptp(h)
    prox = points[h > h.max() - 0.15 * length]
    seed = prox[np.argmax(prox @ medial)]
    centre, radius = seed - 0.05 * length * medial, 0.05 * length
    for _ in range(5):
        near = prox[np.abs(np.linalg.norm(prox - centre, axis=1) - radius) < 0.1 * radius]
        centre, radius = _sphere(near)
    head = centre
    v = points[triangles]
    centres, normals = v.mean(axis=1), np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    distal = centres @ up < h.min() + 0.12 * length
    middle = centres[distal].mean(axis=0)
    back = distal & (normals @ -anterior > 0.3) & ((centres - middle) @ -anterior > 0)
    condyles = [_sphere(centres[back & (s * (centres - middle) @ right > 0.012 * length)])[0] for s in (1, -1)]
    y = _unit(head - 0.5 * (condyles[0] + condyles[1]))
    z = condyles[0] - condyles[1]
    z = _unit(z - (z @ y) * y)
    return y, np.cross(y, z)


def femurs(folder: Path, only):
    """(name, path, truth up, truth anterior, side) for each femur present."""
    from femstudy.meshing.builtin_femur import BUILTIN_STL

    found = [("builtin", BUILTIN_STL, (0, 0, 1), (0, 1, 0), "left")]
    if TLEM2.is_file():
        found.append(("tlem2", TLEM2, (0, 1, 0), (1, 0, 0), "right"))
    else:
        print(f"(TLEM 2.0 femur not found at {TLEM2}; skipped)")
    for name, (up, anterior, side) in FURTHER_FEMURS.items():
        path = folder / f"{name}.stl"
        if path.is_file():
            found.append((name, path, up, anterior, side))
        else:
            print(f"({name} not found at {path}; skipped)")
    return [f for f in found if not only or f[0] in only]


def random_pose(rng, i: int):
    """Rotation, mirroring, translation [mm], units and decimation of pose ``i``."""
    from scipy.spatial.transform import Rotation

    return dict(rotation=Rotation.random(random_state=rng).as_matrix(), mirror=i % 2 == 1,
                shift_mm=rng.uniform(-1000, 1000, 3), units=str(rng.choice(list(UNITS))),
                reduction=float(rng.uniform(0.0, 0.9)))


def posed(points, triangles, pose):
    """The surface in ``pose``, in the pose's units, outward-oriented (as read_surface gives it)."""
    import pyvista as pv

    m = np.diag([-1.0, 1, 1]) if pose["mirror"] else np.eye(3)
    p = points @ (pose["rotation"] @ m).T + pose["shift_mm"]
    t = triangles[:, ::-1] if pose["mirror"] else triangles
    if pose["reduction"] > 0:
        poly = pv.PolyData.from_regular_faces(p, t).decimate(pose["reduction"], volume_preservation=True)
        p, t = np.asarray(poly.points, float), poly.regular_faces
    return p / UNITS[pose["units"]], t, pose["rotation"] @ m


def evidence_row(name: str, frame) -> str:
    """What the detection measured on the unposed femur."""
    proximal = frame.evidence["proximal_end"]
    prox, knee = frame.evidence["ends"][proximal], frame.evidence["ends"]["-" if proximal == "+" else "+"]

    def ratio(end):
        return end["second_cap_mm"]["coverage"] / end["best_cap_mm"]["coverage"] if end["second_cap_mm"] else float("nan")

    e = frame.evidence
    return (f"{name:<18} {frame.side:>5} {prox['best_cap_mm']['radius']:>9.1f} {prox['best_cap_mm']['coverage']:>8.2f} "
            f"{knee['best_cap_mm']['coverage']:>8.2f} {ratio(knee):>5.2f} {ratio(prox):>8.2f} "
            f"{abs(e['condyle_offset_mm']):>11.1f} {abs(e['shaft_bow_mm']):>6.1f} {e['head_forward_angle_deg']:>12.1f}")


def main() -> int:
    sys.path.insert(0, str(REPO))
    from femstudy.casefile import GeometrySpec
    from femstudy.errors import UserError
    from femstudy.meshing.frame import build_frame
    from femstudy.meshing.surface import read_surface

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--femurs", type=Path, default=REPO.parent / "femurs", help="folder of further femur STLs")
    ap.add_argument("--only", nargs="+", help="femur names")
    args = ap.parse_args()
    print("command: python " + " ".join(shlex.quote(a) for a in [str(Path(__file__).relative_to(REPO))] + sys.argv[1:]))
    head = (f"{'femur':<18} {'tris':>6} {'read_s':>6} {'poses':>5} {'pass':>4} {'units':>5} {'prox':>4} {'side':>4} "
            f"{'axis_p50':>8} {'axis_max':>8} {'ant_p50':>7} {'ant_max':>7} {'invar_max':>9} {'det_s_p50':>9} "
            f"{'det_s_max':>9}  ref_vs_truth_deg")
    evidence_head = (f"{'femur':<18} {'side':>5} {'head_r_mm':>9} {'head_cov':>8} {'knee_cov':>8} {'lobes':>5} "
                     f"{'prox_2nd':>8} {'condyles_mm':>11} {'bow_mm':>6} {'head_fwd_deg':>12}")
    rows, evidence, failures = [], [], []
    for name, path, up, anterior, side in femurs(args.femurs, args.only):
        start = time.perf_counter()
        surf = read_surface(path)
        read_s = time.perf_counter() - start
        spec = GeometrySpec()
        base, _ = build_frame(surf.points, surf.triangles, spec)
        evidence.append(evidence_row(name, base))
        ref_up, ref_ant = landmark_frame(surf.points, surf.triangles, up, anterior, side)
        if name in ("builtin", "tlem2"):
            note = f"landmark frame vs authority: up {_angle(ref_up, up):.1f}, anterior {_angle(ref_ant, anterior):.1f}"
            true_up, true_ant = _unit(up), _unit(anterior)
        else:
            note = f"coarse vs landmark: up {_angle(ref_up, up):.1f}, anterior {_angle(ref_ant, anterior):.1f}"
            true_up, true_ant = ref_up, ref_ant
        rng = np.random.default_rng(args.seed)
        stats = {k: [] for k in ("units", "prox", "side", "axis", "ant", "invar", "seconds", "pass")}
        for i in range(args.poses):
            pose = random_pose(rng, i)
            p, t, M = posed(surf.points, surf.triangles, pose)
            truth_side = side if not pose["mirror"] else {"left": "right", "right": "left"}[side]
            start = time.perf_counter()
            try:
                f, _ = build_frame(p, t, spec)
            except UserError as exc:
                failures.append(f"{name} pose {i}: {exc}")
                stats["pass"].append(False)
                continue
            stats["seconds"].append(time.perf_counter() - start)
            axis_err = _angle(f.up, M @ true_up)
            ant_err = _angle(f.anterior, M @ true_ant)
            ok = dict(units=f.units == pose["units"], prox=axis_err < 90, side=f.side == truth_side,
                      axis=axis_err <= LONG_AXIS_TOL_DEG, ant=ant_err <= ANTERIOR_TOL_DEG)
            for k in ("units", "prox", "side"):
                stats[k].append(ok[k])
            stats["axis"].append(axis_err)
            stats["ant"].append(ant_err)
            stats["invar"].append(max(_angle(f.up, M @ base.up), _angle(f.anterior, M @ base.anterior)))
            stats["pass"].append(all(ok.values()))
            if not all(ok.values()):
                failures.append(f"{name} pose {i}: {', '.join(k for k, v in ok.items() if not v)} wrong "
                                f"(axis {axis_err:.1f} deg, anterior {ant_err:.1f} deg, {len(t)} triangles, {pose['units']})")
        s = stats
        if not s["seconds"]:
            continue
        rows.append(f"{name:<18} {len(surf.triangles):>6} {read_s:>6.1f} {args.poses:>5} {sum(s['pass']):>4} "
                    f"{sum(s['units']):>5} {sum(s['prox']):>4} {sum(s['side']):>4} {np.median(s['axis']):>8.1f} "
                    f"{max(s['axis']):>8.1f} {np.median(s['ant']):>7.1f} {max(s['ant']):>7.1f} {max(s['invar']):>9.1f} "
                    f"{np.median(s['seconds']):>9.2f} {max(s['seconds']):>9.2f}  {note}")
        print(rows[-1], flush=True)
    print("\n" + head + "\n" + "\n".join(rows))
    print("\nunposed evidence:\n" + evidence_head + "\n" + "\n".join(evidence))
    print("\ncolumns: tris = triangles of the file; read_s = read_surface time; pass = poses with units, proximal end "
          f"and side right, long axis within {LONG_AXIS_TOL_DEG:g} deg and anterior within {ANTERIOR_TOL_DEG:g} deg of "
          "the truth; units/prox/side = poses with each right; axis/ant = angle to the truth's long axis / anterior "
          "[deg]; invar_max = largest angle between a pose's detected axes and the unposed detection carried along; "
          "det_s = build_frame time [s]; ref_vs_truth_deg = the landmark frame against the authority (builtin, "
          "tlem2) or against the coarse orientation read off pictures (the others, whose truth it is)")
    print("evidence: head_r/head_cov = radius and coverage of the best cap at the proximal end; knee_cov = the "
          "same at the distal end; lobes = coverage of the second cap over the first there (condyles: >= 0.6); "
          "prox_2nd = the same ratio at the proximal end; condyles_mm = distance of the distal condyles behind the "
          "shaft line; bow_mm = forward bow of the shaft; head_fwd_deg = angle of the head centre's offset from the "
          "shaft line ahead of the medial axis (a rough anteversion)")
    for line in failures:
        print("FAILED " + line)
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
