"""Several cases at once (e.g. the thesis's sites) and their combined table."""

from __future__ import annotations

import json
from pathlib import Path

from femstudy import atomic
from femstudy.meshing.cache import DEFAULT_CACHE_DIR
from femstudy.study.report import study_discussion, study_table

#: Disk a case's results need, checked before it runs [bytes]: twice the 50 MB of the default
#: case's folder (fields of 7 frames of a 60,000-node mesh), a tenth of that without fields.
RESULTS_BYTES_WITH_FIELDS, RESULTS_BYTES = 100e6, 10e6


def write_study(folder: Path, summaries: list[dict]) -> Path:
    """Write ``study.md`` (table beside Tables 5-14/5-15 plus discussion) and ``study.json``."""
    text = "\n".join(["# Drilling study: all sites", "", study_table(summaries), "", study_discussion(summaries)])
    with atomic.atomic_folder(folder) as tmp:
        (tmp / "study.md").write_text(text, encoding="utf-8")
        (tmp / "study.json").write_text(json.dumps(
            [{"case": s["case"]["name"], "site": s["site"]["name"], "results": s["results"],
              "out_of_range": s.get("out_of_range", [])} for s in summaries], indent=2), encoding="utf-8")
    return Path(folder) / "study.md"


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
    from femstudy.study.femur import femur_spec
    from femstudy.study.feasibility import preflight
    from femstudy.study.run import run_study
    from femstudy.writable import check_output_folder, require_free_space

    require(out is None or len(case_files) == 1, "--out names one results folder: give one case file")
    cases = [load_case(path, bones_dir) for path in case_files]
    overrides = {**({"drilling.bone": bone} if bone is not None else {}),
                 **({"mesh.size_mm": mesh_size_mm} if mesh_size_mm is not None else {})}
    if overrides:  # validated like the case files' own values
        cases = [with_overrides(case, overrides) for case in cases]
        check_references(cases[0], bones_dir)
    names = [case.name for case in cases]
    twice = next((name for name in names if names.count(name) > 1), None)
    require(twice is None, f"two of the cases are named '{twice}': their results would overwrite each other in "
                           f"results/{twice}; give each case its own name")
    targets = [out or Path("results") / case.name for case in cases]
    for case, target in zip(cases, targets):
        surface = femur_spec(case).surface
        check_output_folder(target, "results", inputs=[*case_files, *([surface] if surface else [])],
                            cache_dir=cache_dir)
        require_free_space(target, RESULTS_BYTES_WITH_FIELDS if case.output.fields else RESULTS_BYTES)
    if len(cases) > 1:
        check_output_folder(study_out, "the combined table", inputs=case_files, cache_dir=cache_dir)
        require(Path(study_out).resolve() not in {Path(t).resolve() for t in targets},
                f"--study-out {study_out} is also a case's results folder; name another")
    for case in cases:  # every case's inputs judged before the first one runs
        preflight(case, cache_dir, bones_dir, force)
    results = [run_study(case, target, cache_dir=cache_dir, solver=solver, bones_dir=bones_dir, force=force,
                         keep_solutions=keep_solutions, executor=executor)
               for case, target in zip(cases, targets)]
    table = write_study(study_out, [r.to_json() for r in results]) if len(results) > 1 else None
    return results, table
