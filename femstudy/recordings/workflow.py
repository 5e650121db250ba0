"""``calibrate``: recordings on disk → a calibrated bone set, its tables and figures.

Reads and checks every recording, processes the cuts, runs the calibration pipeline
(femstudy.recordings.pipeline), writes the tables and figures to a folder atomically and
saves the bone set in the bone library.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

from femstudy.errors import UserError, require
from femstudy.recordings.pipeline import CalibrationResult

log = logging.getLogger(__name__)

FIGURES = ("fits.png", "power_law.png", "validation.png", "normality.png", "ann_neurons.png")


def recording_paths(items, what: str) -> list[Path]:
    """Files as given, folders expanded to their recordings (any suffix in
    :func:`~femstudy.recordings.formats.registry.recording_suffixes`, sorted); names must be unique."""
    from femstudy.recordings.formats.registry import recording_suffixes

    suffixes = recording_suffixes()

    paths = []
    for item in map(Path, items):
        if item.is_dir():
            found = sorted(p for p in item.iterdir() if p.suffix.lower() in suffixes and p.is_file())
            require(found, f"{what}: folder {item} has no recordings ({', '.join(suffixes)} files)")
            paths += found
        else:
            require(item.exists(), f"{what}: recording {item} does not exist")
            paths.append(item)
    names = [p.name for p in paths]
    duplicate = next((n for n in names if names.count(n) > 1), None)
    require(duplicate is None, f"{what}: two recordings are named {duplicate}; names must be unique")
    return paths


def calibrate(runs, validate=(), *, name: str = "calibrated", out: Path | None = None, holdout: int = 2,
              metadata: dict | None = None, override: bool = False, columns: str | dict | None = None,
              cutoff_hz: float | None = None,
              neurons: bool = True, figures: bool = True, bones_dir: Path | None = None) -> CalibrationResult:
    """Calibrate the chip-evacuation model's friction on recordings and save the bone set.

    Parameters
    ----------
    runs : list of path
        Recordings, or folders of them, at four or more (feed, speed) conditions.
    validate : list of path
        Held-out recordings (else ``holdout`` replicates per condition are held out).
    name : str
        Name of the bone set to save (letters, digits, '.', '_', '-').
    out : Path, optional
        Folder for tables and figures (default results/calibration/<name>), replaced as a whole.
    metadata, override
        Metadata for every recording (``{"spindle_rpm": 1500}``) and whether it wins over a
        recording's own header.
    columns : str or dict, optional
        Which file columns hold time, thrust and torque, e.g. ``"time=Zeit,thrust=Fz,torque=Mz"``
        (see :func:`~femstudy.recordings.reader.read_recording`).
    cutoff_hz : float, optional
        Low-pass cut-off [Hz] (default from the feed, Table 4-4).
    neurons, figures : bool
        Run the neural-network neuron study; draw the figures.
    bones_dir : Path, optional
        Bone library to save in (default the user's data folder).

    Returns
    -------
    CalibrationResult
        ``files`` maps "folder", "report", "bone_set" to what was written.

    Examples
    --------
    >>> result = calibrate(["demo/calibration"], ["demo/validation"], name="mybone")   # doctest: +SKIP
    >>> result.table()[0]["mu_f"]                                                     # doctest: +SKIP
    0.213
    """
    from femstudy import atomic
    from femstudy.drilling.friction import BUILTIN_TABLES, default_bone_library
    from femstudy.recordings import figures as draw, read_recording, report
    from femstudy.recordings.pipeline import calibrate as run_pipeline
    from femstudy.recordings.formats.size import MAX_ANALYSED_SAMPLES, check_recording_size
    from femstudy.recordings.processing import process
    from femstudy.writable import check_output_folder

    require(re.fullmatch(r"[A-Za-z0-9._-]+", name) is not None and not name.startswith("."),
            f"--name may contain only letters, digits, '.', '_' and '-', got '{name}'")
    require(name not in BUILTIN_TABLES, f"--name '{name}' is a built-in bone set; choose another name")
    require(holdout >= 0, f"--holdout must be >= 0, got {holdout}")
    require(cutoff_hz is None or cutoff_hz > 0, f"--cutoff-hz must be positive, got {cutoff_hz}")
    out = Path(out) if out is not None else Path("results") / "calibration" / name
    cal_paths, val_paths = recording_paths(runs, "RUNS"), recording_paths(validate, "--validate")
    check_output_folder(out, "the calibration", inputs=[*runs, *validate])
    clash = {p.name for p in cal_paths} & {p.name for p in val_paths}
    if clash:
        raise UserError(f"{sorted(clash)[0]} is both a calibration and a validation recording")
    for path in cal_paths + val_paths:
        check_recording_size(path, MAX_ANALYSED_SAMPLES, "calibrate")

    recordings = []
    for path in cal_paths + val_paths:
        rec = read_recording(path, metadata or {}, override_header=override, columns=columns)
        for note in rec.notes:
            if "overrides" in note:
                log.warning("%s: %s", path.name, note)
        require(rec.torque_Nmm is not None, f"recording {rec.name} has no torque column (torque_Nmm or torque_Nm); "
                                            f"calibrating mu_f and mu_w needs the torque (Eq 4.4)")
        recordings.append(rec)
    conditions = sorted({(float(f"{r.feed_mm_s:.6g}"), float(f"{r.spindle_rpm:.6g}"))
                         for r in recordings[: len(cal_paths)]})
    require(len(conditions) >= 4, f"the power law (Eq 4.5) needs calibration runs at four or more (feed, speed) "
                                  f"conditions; these cover {len(conditions)}: "
                                  + ", ".join(f"{f:g} mm/s {n:g} rpm" for f, n in conditions))
    log.info("read %d recordings", len(recordings))
    processed = []
    for k, rec in enumerate(recordings, 1):
        processed.append(process(rec, cutoff_hz=cutoff_hz))
        log.info("processed %d/%d recordings", k, len(recordings),
                 extra={"progress": ("recordings", k, len(recordings))})
    result = run_pipeline(processed[: len(cal_paths)], processed[len(cal_paths):], name=name, holdout=holdout,
                          neurons=range(1, 11) if neurons else None)

    target = (default_bone_library() if bones_dir is None else Path(bones_dir)) / f"{name}.toml"
    text = report.summary_text(result, bone_path=target)
    with atomic.atomic_folder(out) as tmp:
        atomic.write_text(tmp / "report.txt", text + "\n")
        atomic.write_text(tmp / "runs.csv", report.runs_csv(result))
        atomic.write_text(tmp / "conditions.csv", report.conditions_csv(result))
        atomic.write_text(tmp / f"{name}.toml", result.bone.to_toml())
        held_out = result.by_role("held out", "validation")
        if held_out:
            atomic.write_text(tmp / "validation.csv", report.validation_csv(result))
        if result.ann is not None:
            atomic.write_text(tmp / "ann_neurons.csv", report.ann_csv(result))
        if figures:
            draw.plot_condition_fits(tmp / "fits.png", result)
            draw.plot_power_law(tmp / "power_law.png", result, report.truth_power_law(result))
            if held_out:
                draw.plot_validation(tmp / "validation.png", result)
            if result.normality:
                draw.plot_normality(tmp / "normality.png", result.normality)
            if result.ann is not None:
                draw.plot_neuron_study(tmp / "ann_neurons.png", result.ann)
            log.info("drew the figures")
    try:
        atomic.write_text(target, result.bone.to_toml())
    except OSError as exc:
        raise UserError(f"cannot save bone set to {target}: {exc.strerror or exc} (the tables are in {out}; "
                        f"set FEMSTUDY_BONES to a writable folder)") from None
    result.files.update(folder=out, report=text, bone_set=target)
    return result
