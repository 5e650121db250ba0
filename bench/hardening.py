"""The examples of issue #34 run as a careless user would: each must end with one line and
exit status 2 (or, with --force, a marked result) within 10 s where the input is refused,
with the user's file in ``mydata/`` still there.

    python bench/hardening.py [--cache DIR] [--out FILE.md]

Every example runs as its own ``femstudy`` process in a fresh folder, timed from outside;
the table lists exit status, stderr lines other than progress, wall time and the line. With
``--cache`` (a mesh cache holding the default case's mesh, e.g. the repository's
``.femstudy-cache``) the examples that need the mesh (a depth beyond the bone) are refused
after loading it; without it they mesh first (a minute of TetWild).
"""

from __future__ import annotations

import argparse
import os
import re
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CASE = (REPO / "cases" / "middiaphysis.toml").read_text().replace(
    'convergence = "convergence/middiaphysis-hole.json"', "")


def case(folder: Path, name: str, *edits: tuple[str, str], append: str = "") -> str:
    text = CASE
    for old, new in edits:
        text = text.replace(old, new)
    (folder / f"{name}.toml").write_text(text + append)
    return f"{name}.toml"


def stl(folder: Path, name: str, announce: int | None = None, scale: float = 1.0) -> None:
    from femstudy.meshing.builtin_femur import BUILTIN_STL

    raw = bytearray(BUILTIN_STL.read_bytes())
    if scale != 1.0:
        import numpy as np

        n = struct.unpack("<I", raw[80:84])[0]
        body = np.frombuffer(bytes(raw[84:84 + 50 * n]), dtype=np.dtype([("v", "<f4", 12), ("a", "<u2")])).copy()
        body["v"] *= np.float32(scale)
        raw[84:84 + 50 * n] = body.tobytes()
    if announce is not None:
        raw[80:84] = struct.pack("<I", announce)
    (folder / name).write_bytes(bytes(raw))


def recording(folder: Path, name: str, rows: int = 9000, torque=None, thrust_scale: float = 1.0) -> str:
    lines = ["# feed_mm_s = 1.5", "# spindle_rpm = 1500", "time_s,thrust_N,torque_Nmm"]
    for k in range(rows):
        t = k / 1000.0
        thrust = (20.0 * (t > 2) + 0.1 * (k % 7)) * thrust_scale
        lines.append(f"{t:.4f},{thrust:.6g},{torque if torque is not None else 2 * thrust + 0.1 * (k % 5):.6g}")
    (folder / name).write_text("\n".join(lines) + "\n")
    return name


def examples(work: Path, cache: Path) -> list[tuple[str, list[str]]]:
    """(what, command) of each example; files are written into ``work``; ``cache`` is the
    mesh cache the commands use."""
    stl(work, "femur_200M.stl", announce=200_000_000)
    stl(work, "femur_1e30.stl", scale=1e30)
    with open(work / "femur_12M.stl", "wb") as f:  # sparse: a consistent header and size, no disk
        f.write(b"x".ljust(80) + struct.pack("<I", 12_000_000))
        f.truncate(84 + 50 * 12_000_000)
    with open(work / "rows_10M.csv", "w") as f:
        f.write("# feed_mm_s = 1.5\n# spindle_rpm = 1500\ntime_s,thrust_N,torque_Nmm\n")
        block = "".join(f"{k / 1e4:.4f},{k % 7},{k % 5}\n" for k in range(100_000))
        for _ in range(100):
            f.write(block)
    grid = ", ".join(f"{1.8 + k * 1e-4:.4f}" for k in range(1000))
    (work / "grid.toml").write_text(f'case = "base.toml"\n[grid]\n"drilling.feed_mm_s" = [{grid}]\n'
                                    f'"drilling.spindle_rpm" = [{", ".join(str(1000 + k) for k in range(1000))}]\n')
    (work / "one_bad.toml").write_text('case = "base.toml"\n[grid]\n"drilling.feed_mm_s" = [2.0, 3.0]\n')
    (work / "report.md").write_text("mine")
    base = case(work, "base")
    rec = recording(work, "rec.csv")
    return [
        ("feed 3.0 mm/s (mu_w 43)", ["run", case(work, "feed3", ("feed_mm_s = 2.0", "feed_mm_s = 3.0"))]),
        ("depth_mm = 100", ["run", case(work, "depth", ("depth_mm = 6.0", "depth_mm = 100"))]),
        ("feed_mm_s = true", ["run", case(work, "true", ("feed_mm_s = 2.0", "feed_mm_s = true"))]),
        ("dead torque channel", ["diagnose", recording(work, "dead.csv", torque=3.5), "--model", "allotta"]),
        ("--out mydata", ["run", base, "--out", "mydata"]),
        ("--out the mesh cache", ["run", base, "--out", str(cache)]),
        ("case named .", ["run", case(work, "dot", ('name = "middiaphysis"', 'name = "."'))]),
        ("two cases, one name", ["run", base, case(work, "twin")]),
        ("diagnose --report FILE", ["diagnose", rec, "--model", "allotta", "--report", "report.md"]),
        ("mesh --out mydata", ["mesh", base, "--out", "mydata"]),
        ("calibrate --out mydata", ["calibrate", rec, "--out", "mydata"]),
        ("rpm 1e-9", ["run", case(work, "rpm", ("spindle_rpm = 1500", "spindle_rpm = 1e-9"))]),
        ("E = 1e-300", ["run", case(work, "e", append="\n[materials.cortical]\nyoungs_modulus_GPa = 1e-300\n")]),
        ("Rayleigh = inf", ["run", case(work, "ray", ("[time]", "[analysis]\nrayleigh_alpha_per_s = inf\n[time]"))]),
        ("--mesh-size inf", ["run", base, "--mesh-size", "inf"]),
        ("--mesh-size 1e9", ["run", base, "--mesh-size", "1e9"]),
        ("--cortex-mm 1e308", ["diagnose", rec, "--model", "allotta", "--cortex-mm", "1e308"]),
        ("thrust x 1e300", ["diagnose", recording(work, "huge.csv", thrust_scale=1e300), "--model", "allotta"]),
        ("STL announcing 200M triangles", ["run", case(work, "s200", ('surface = "builtin"', 'surface = "femur_200M.stl"'))]),
        ("STL of 12M triangles", ["run", case(work, "s12", ('surface = "builtin"', 'surface = "femur_12M.stl"'))]),
        ("--out .", ["run", base, "--out", "."]),
        ("case named ..", ["run", case(work, "dotdot", ('name = "middiaphysis"', 'name = ".."'))]),
        ("--json unwritable", ["diagnose", rec, "--model", "allotta", "--json", "report.md/d.json"]),
        ("scheduler not a URL", ["sweep", base, "--sizes", "16,12,8", "--scheduler", "my-cluster"]),
        ("synth --dataset .", ["synth", "--dataset", "."]),
        ("femur scaled by 1e30", ["run", case(work, "s30", ('surface = "builtin"', 'surface = "femur_1e30.stl"'))]),
        ("10 M-row recording", ["diagnose", "rows_10M.csv", "--model", "allotta"]),
        ("site_size_mm = 1e-6", ["run", case(work, "site", ("site_size_mm = 1.0", "site_size_mm = 1e-6"))]),
        ("site_size_mm = 0.05", ["run", case(work, "site05", ("site_size_mm = 1.0", "site_size_mm = 0.05"))]),
        ("1000 x 1000 sweep grid", ["sweep", "grid.toml"]),
        ("grid with one impossible point", ["sweep", "one_bad.toml"]),
        ("convergence sweep, one size", ["sweep", base, "--sizes", "8"]),
        ("convergence sweep, 8,8,8", ["sweep", base, "--sizes", "8,8,8"]),
        ("NaN in site.direction", ["run", case(work, "dir", ('direction = "anterior"', "direction = [nan, 1, 0]"))]),
        ("inf in long_axis", ["run", case(work, "axis", ('surface = "builtin"', 'surface = "builtin"\nlong_axis = [inf, 0, 1]'))]),
        ("folder as the case file", ["run", "mydata"]),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, help="mesh cache holding the default case's mesh")
    parser.add_argument("--out", type=Path, help="also write the table here (Markdown)")
    args = parser.parse_args()
    rows = ["| example | exit | lines | seconds | stderr |", "|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="femstudy-hardening-") as tmp:
        work = Path(tmp)
        (work / "mydata").mkdir()
        (work / "mydata" / "notes.txt").write_text("precious")
        cache = (args.cache or work / ".femstudy-cache").resolve()
        env = {**os.environ, "MPLBACKEND": "Agg", "FEMSTUDY_CACHE": str(cache), "FEMSTUDY_BONES": str(work / "bones")}
        for what, command in examples(work, cache):
            start = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "femstudy", *command], cwd=work, env=env,
                                  capture_output=True, text=True)
            seconds = time.perf_counter() - start
            lines = [line for line in proc.stderr.splitlines() if line and not line.startswith("[")]
            shown = re.sub(r"\s+", " ", lines[-1] if lines else "")[:160].replace("|", "/")
            rows.append(f"| {what} | {proc.returncode} | {len(lines)} | {seconds:.1f} | {shown} |")
            print(rows[-1], flush=True)
            assert (work / "mydata" / "notes.txt").read_text() == "precious", what
    text = "\n".join(rows) + "\n"
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
