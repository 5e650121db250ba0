"""Several cases at once (e.g. the thesis's sites) and their combined table."""

from __future__ import annotations

import json
from pathlib import Path

from femstudy import atomic
from femstudy.meshing.cache import DEFAULT_CACHE_DIR
from femstudy.study.report import study_discussion, study_table


def write_study(folder: Path, summaries: list[dict]) -> Path:
    """Write ``study.md`` (table beside Tables 5-14/5-15 plus discussion) and ``study.json``."""
    text = "\n".join(["# Drilling study: all sites", "", study_table(summaries), "", study_discussion(summaries)])
    folder = Path(folder)
    atomic.write_text(folder / "study.md", text)
    atomic.write_text(folder / "study.json", json.dumps(
        [{"case": s["case"]["name"], "site": s["site"]["name"], "results": s["results"]} for s in summaries], indent=2))
    return folder / "study.md"


def run_cases(case_files: list[Path], out: Path | None = None, study_out: Path = Path("results/study"), *,
              mesh_size_mm: float | None = None, cache_dir: Path = DEFAULT_CACHE_DIR, solver: str = "auto",
              bones_dir: Path | None = None, bone: str | None = None, force: bool = False,
              keep_solutions: bool = True, executor=None) -> tuple[list, Path | None]:
    """Run the study of every case file into results/<case name> (or ``out`` for one case);
    with several cases also the combined table in ``study_out``.

    Every file, and every results location, is checked before any work starts.

    Parameters
    ----------
    case_files : list of Path
    out : Path, optional
        Results folder of a single case.
    study_out : Path
        Folder of the combined table (several cases).
    mesh_size_mm, cache_dir, solver, bones_dir, force, keep_solutions, executor
        As for :func:`femstudy.run_study`.
    bone : str, optional
        Replaces every case's ``drilling.bone`` (e.g. "bovine" to repeat a human-femur study
        with the bovine friction calibration).

    Returns
    -------
    (list of StudyResult, Path of study.md or None)

    Examples
    --------
    >>> results, table = run_cases([Path("cases/middiaphysis.toml"), Path("cases/proximal.toml")])  # doctest: +SKIP
    """
    from femstudy.casefile import check_references, load_case, with_overrides
    from femstudy.errors import require
    from femstudy.study.run import run_study
    from femstudy.writable import require_writable_parent

    require(out is None or len(case_files) == 1, "--out names one results folder: give one case file")
    require(mesh_size_mm is None or mesh_size_mm > 0, f"--mesh-size must be positive, got {mesh_size_mm}")
    cases = [load_case(path, bones_dir) for path in case_files]
    if bone is not None:
        cases = [with_overrides(case, {"drilling.bone": bone}) for case in cases]
        check_references(cases[0], bones_dir)
    targets = [out or Path("results") / case.name for case in cases]
    for target in targets:
        require_writable_parent(target)
    if len(cases) > 1:
        require_writable_parent(study_out)
    results = [run_study(case, target, mesh_size_mm=mesh_size_mm, cache_dir=cache_dir, solver=solver,
                         bones_dir=bones_dir, force=force, keep_solutions=keep_solutions, executor=executor)
               for case, target in zip(cases, targets)]
    table = write_study(study_out, [r.to_json() for r in results]) if len(results) > 1 else None
    return results, table
