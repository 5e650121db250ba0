"""The whole study as a user runs it, against the bare static solve of the same mesh.

    python bench/study_run.py [--tree DIR] [--label LABEL] [--repeats 2] [--out FILE.md]

Each measurement is a separate process timed from outside (wall time, peak resident memory
of its largest process, and the peak of all its processes' summed PSS, for a study whose lanes
fork; bench/peers/measure.py), in this order:

  bare static     bench/peers/femstudy_run.py --analysis static on the case's cached mesh
  cached run      femstudy run cases/middiaphysis.toml (the mesh and, since the cold run, the
                  kept solutions of its stiffness matrices and the answers of its hole models,
                  sensitivity and resolved run kept: no factorisation; femstudy.kept_answers)
  other loads     the same case at another feed rate: the kept answers miss, the kept
                  solutions serve (what a study that changes only the loads costs)
  one process     the same with --serial (no lanes forked: femstudy.lanes)
  factorising     the same with --no-kept-solutions (the mesh cached, every matrix factorised)
  cold run        the same with an empty mesh cache (TetWild included)
  resolved 16 mm  the bare static solve at 16 mm (which caches that mesh), then the case at
                  --mesh-size 16 with step_s = 1e-4 (30,000 steps over 3 s)
  refusals        mesh.size_mm = 0.2 and step_s = 1e-7 (must exit 2 with one line)

``--tree DIR`` runs the ``femstudy`` commands from another checkout (e.g. an earlier commit
exported with ``git archive``) for a before/after comparison; the bare static solve always
uses this checkout. The table goes to stdout and, with ``--out``, to a Markdown file.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.peers.measure import measure  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
CASE = "cases/middiaphysis.toml"


def femstudy_command(tree: Path, *args: str) -> list[str]:
    """``python -m femstudy ...`` importing the package from ``tree``."""
    return [sys.executable, "-c", f"import sys; sys.path.insert(0, {str(tree)!r}); "
            "from femstudy.cli import main; sys.exit(main())", *args]


def bare_static(size_mm: float, work: Path, cache: Path) -> list[str]:
    """Build the benchmark model of the case at ``size_mm`` (not timed); the static solve's command."""
    from bench import run_all
    from femstudy.casefile import load_case

    run_all.CACHE_DIR = cache
    model = work / f"model-{size_mm:g}.npz"
    run_all.build_model("femur", load_case(REPO / CASE), size_mm).save(model)
    return [sys.executable, str(REPO / "bench/peers/femstudy_run.py"), str(model), str(work / "u.npz"),
            "--analysis", "static"]


def variant(tree: Path, work: Path, name: str, edit) -> Path:
    """A copy of the tree's case file with ``edit`` applied to its text, surface kept built-in,
    its hole-convergence record (a path relative to the case) pointing at the tree's."""
    case = tree / CASE
    text = re.sub(r'(convergence\s*=\s*")([^"]+)"', lambda m: f'{m[1]}{(case.parent / m[2]).as_posix()}"',
                  case.read_text())
    path = work / f"{name}.toml"
    path.write_text(edit(text))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=REPO, help="checkout whose femstudy runs the study")
    parser.add_argument("--label", default="this checkout")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--no-resolved", action="store_true",
                        help="skip the 30,000-step run (an earlier version would try to hold every step)")
    parser.add_argument("--timeout-s", type=float, default=600.0, help="a run is killed after this (600)")
    parser.add_argument("--quick", action="store_true",
                        help="only the cold run, the bare static solve at 8 mm, the cached run and the other loads")
    args = parser.parse_args()
    tree = args.tree.resolve()
    rows = []
    with tempfile.TemporaryDirectory(prefix="femstudy-bench-") as tmp:
        work = Path(tmp)
        cache = work / "cache"
        env = dict(os.environ, FEMSTUDY_CACHE=str(cache))

        def timed(label, command, repeats=args.repeats, expect=0, cwd=tree, environment=env, timeout_s=None):
            runs = []
            for k in range(repeats):
                m = measure(command, work / f"{len(rows)}-{k}.log", cwd=cwd, env=environment,
                            timeout_s=timeout_s or args.timeout_s)
                runs.append(m)
                if m.returncode != expect:  # reported, not fatal: an earlier version may fail
                    break
            wall = statistics.median(m.wall_s for m in runs)
            peak = statistics.median(m.peak_MB for m in runs)
            tree = statistics.median(m.tree_peak_MB for m in runs)
            last = (runs[-1].log.read_text(errors="replace").strip().splitlines() or [""])[-1]
            if runs[-1].returncode != expect:
                last = f"exit {runs[-1].returncode} (expected {expect}): {last}"
            rows.append((label, wall, peak, tree, last if expect or runs[-1].returncode != expect else ""))
            print(f"{label}: {wall:.1f} s, {peak:.0f} MB (all processes {tree:.0f} MB)", flush=True)
            return wall, peak

        run = ["run", CASE, "--out", str(work / "out"), "--quiet"]
        timed("cold run (empty mesh cache)", femstudy_command(tree, *run), repeats=1)
        static8 = timed("bare static solve, 8 mm", bare_static(8.0, work, cache), cwd=REPO)
        cached = timed("cached run", femstudy_command(tree, *run))
        other_loads = variant(tree, work, "feed", lambda s: re.sub(r"feed_mm_s\s*=.*", "feed_mm_s = 1.8", s))
        reloaded = timed("cached mesh, other loads (feed 1.8 mm/s: only solutions kept)",
                         femstudy_command(tree, "run", str(other_loads), "--out", str(work / "feed"), "--quiet"),
                         repeats=1)
        if args.quick:
            rows.append(("(--quick: the other measurements not run)", float("nan"), float("nan"), float("nan"), ""))
        if not args.quick and "--serial" in (tree / "femstudy/commands/run.py").read_text():  # lanes
            timed("cached run, one process (--serial)", femstudy_command(tree, *run, "--serial"))
        factorising = None
        if not args.quick and "no-kept-solutions" in (tree / "femstudy/commands/run.py").read_text():
            factorising = timed("cached mesh, factorising (--no-kept-solutions)",
                                femstudy_command(tree, *run, "--no-kept-solutions"))
        static16 = (float("nan"), float("nan"))
        if not args.quick:
            static16 = timed("bare static solve, 16 mm", bare_static(16.0, work, cache), cwd=REPO)  # meshes 16 mm
            resolved = variant(tree, work, "resolved", lambda s: re.sub(r"step_s\s*=.*", "step_s = 0.0001", s))
            label = "resolved 16 mm (cached mesh): run, step 1e-4 s"
            if args.no_resolved:
                rows.append((label, float("nan"), float("nan"), float("nan"), "not run"))
            else:
                timed(label, femstudy_command(tree, "run", str(resolved), "--mesh-size", "16", "--out", str(work / "r16"),
                                              "--quiet"), repeats=1)
            fine = variant(tree, work, "fine", lambda s: re.sub(r"size_mm\s*=.*", "size_mm = 0.2", s, count=1))
            timed("refusal: mesh.size_mm = 0.2", femstudy_command(tree, "run", str(fine), "--out", str(work / "f")),
                  repeats=1, expect=2, timeout_s=60.0)
            tiny = variant(tree, work, "tiny", lambda s: re.sub(r"step_s\s*=.*", "step_s = 1e-7", s))
            timed("refusal: step_s = 1e-7", femstudy_command(tree, "run", str(tiny), "--out", str(work / "t")),
                  repeats=1, expect=2, timeout_s=60.0)

    lines = [f"Study runs, femstudy from {args.label} ({time.strftime('%Y-%m-%d %H:%M')}, load average "
             f"{os.getloadavg()[0]:.2f} at the end; medians of {args.repeats} where repeated)", "",
             "| measurement | wall [s] | peak RSS, largest process [MB] | peak PSS, all processes [MB] | message |",
             "|---|---:|---:|---:|---|"]
    lines += [f"| {label} | {wall:.1f} | {peak:.0f} | {tree:.0f} | {message[:160]} |"
              for label, wall, peak, tree, message in rows]
    lines += ["", f"cached run / bare static (8 mm): {cached[0] / static8[0]:.2f} (wall), "
                  f"{cached[1] / static8[1]:.2f} (memory); bare static 16 mm peak {static16[1]:.0f} MB",
              f"cached mesh, other loads / bare static (8 mm): {reloaded[0] / static8[0]:.2f} (wall)"]
    if factorising is not None:
        lines += [f"cached mesh, factorising / bare static (8 mm): {factorising[0] / static8[0]:.2f} (wall), "
                  f"{factorising[1] / static8[1]:.2f} (memory)"]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
