"""Synthetic recordings written to files: one recording, or a calibration data set shaped
like the thesis's (§4.1.1, §5.1–5.2).

Five calibration conditions (Table 4-1) × ``replicates`` runs and two validation conditions
(Table 5-3) × ``validation_replicates`` runs. Each run draws its own friction and initial
force around the generating bone set's power law, with the replicate spread of Appendix B:

- ln μ_f and ln μ_w: standard deviation 0.17 each, so that p = ηMD/S spreads by about 17 %
  (Appendix B: 16 % robust (MAD) and 21 % plain standard deviation of p over 30 trials);
- ln u1, hence ln F_o: standard deviation 0.14 (Appendix B: sd/mean of F_o = 0.140);
- cortical thickness uniform in 5.5–9 mm (Fig 5-1 shows holes of 5.5–11 mm).

Rig effects are drawn per run (noise, ripple, pulsation of 0.3–3 Hz, drift). ``outliers``
calibration runs in different conditions trend differently (friction far off their
condition's, or no clogging at all), like the runs the thesis removed by eye (§5.1); they cut
a thin cortex (5.5–6.5 mm) so that the packed flutes stay below a few hundred newtons. Their
headers say so (``outlier``, ``outlier_reason``).
"""

from __future__ import annotations

import csv
import io
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.drilling.friction import BoneSet, load_bone_set
from femstudy.errors import require
from femstudy.recordings.formats import registry
from femstudy.recordings.reader import Recording, write_recording
from femstudy.recordings.synthetic import Effects, FeedPulsation, Noise, SensorDrift, SpindleRipple, synthesize

#: Table 4-1 calibration conditions and Table 5-3 validation conditions, (f [mm/s], N [rpm]).
log = logging.getLogger(__name__)

CALIBRATION_CONDITIONS = ((1.0, 1000.0), (1.5, 1100.0), (1.5, 1250.0), (1.75, 1500.0), (2.0, 1500.0))
VALIDATION_CONDITIONS = ((1.75, 1250.0), (2.0, 1000.0))
#: (model, μ_f factor, μ_w factor, reason) of the planted outlier runs, used in turn. Each is
#: far outside the replicate spread (ln 2.5 = 5.4 and ln 3.5 = 7.4 standard deviations).
OUTLIER_KINDS = (("clogging", 2.5, 1.0, "mu_f x2.5: flutes packed with chips from the previous hole"),
                 ("allotta", 1.0, 1.0, "no chip clogging: the chips evacuated freely"),
                 ("clogging", 1.0, 3.5, "mu_w x3.5: hole wall friction far higher"))


@dataclass(frozen=True)
class Spread:
    """Replicate-to-replicate spread: standard deviations of ln μ_f, ln μ_w, ln F_o; cortex range."""

    ln_mu_f: float = 0.17
    ln_mu_w: float = 0.17
    ln_initial_force: float = 0.14
    cortex_mm: tuple[float, float] = (5.5, 9.0)


def random_effects(rng: np.random.Generator) -> Effects:
    """Rig imperfections of one run, drawn from plausible ranges."""
    return Effects(
        noise=Noise(thrust_N=rng.uniform(0.2, 0.5), torque_Nmm=rng.uniform(0.5, 1.5)),
        ripple=SpindleRipple(fraction=rng.uniform(0.02, 0.08)),
        pulsation=FeedPulsation(amplitude=rng.uniform(0.05, 0.2),
                                frequency_hz=float(np.exp(rng.uniform(np.log(0.3), np.log(3.0)))),
                                phase_rad=rng.uniform(0, 2 * np.pi)),
        drift=SensorDrift(thrust_N_per_s=rng.uniform(-0.08, 0.08), torque_Nmm_per_s=rng.uniform(-0.3, 0.3),
                          thrust_offset_N=rng.uniform(-1, 1), torque_offset_Nmm=rng.uniform(-3, 3)))


def dataset_recordings(bone: str | BoneSet = "bovine", replicates: int = 10, validation_replicates: int = 2,
                       outliers: int = 3, seed: int = 0, spread: Spread = Spread(),
                       sample_rate_hz: float = 1000.0, effects=random_effects) -> list[tuple[str, Recording]]:
    """(relative path, recording) of every run; deterministic for a given seed.

    ``effects(rng) -> Effects`` draws each run's rig imperfections (default :func:`random_effects`).
    """
    bone_set = load_bone_set(bone) if isinstance(bone, str) else bone
    rng = np.random.default_rng(seed)
    plan = [("calibration", c, r) for c in CALIBRATION_CONDITIONS for r in range(1, replicates + 1)]
    plan += [("validation", c, r) for c in VALIDATION_CONDITIONS for r in range(1, validation_replicates + 1)]
    outlier_runs = {}
    if outliers:
        conditions = rng.permutation(len(CALIBRATION_CONDITIONS))
        for k in range(min(outliers, len(CALIBRATION_CONDITIONS) * replicates)):
            cond = int(conditions[k % len(conditions)])
            outlier_runs[(CALIBRATION_CONDITIONS[cond], int(rng.integers(1, replicates + 1)))] = \
                OUTLIER_KINDS[k % len(OUTLIER_KINDS)]
    runs = []
    for role, (feed, rpm), replicate in plan:
        mu_f0, mu_w0 = bone_set.friction(feed, rpm)
        mu_f = mu_f0 * np.exp(spread.ln_mu_f * rng.standard_normal())
        mu_w = mu_w0 * np.exp(spread.ln_mu_w * rng.standard_normal())
        u1 = bone_set.u1_MPa * np.exp(spread.ln_initial_force * rng.standard_normal())
        kind = outlier_runs.get(((feed, rpm), replicate)) if role == "calibration" else None
        cortex = float(rng.uniform(*spread.cortex_mm))
        if kind:
            mu_f, mu_w = mu_f * kind[1], mu_w * kind[2]
            cortex = spread.cortex_mm[0] + (cortex - spread.cortex_mm[0]) * 1.0 / np.ptp(spread.cortex_mm)
        extra = {"role": role, "replicate": replicate, "condition_mu_f": float(mu_f0),
                 "condition_mu_w": float(mu_w0), "outlier": kind is not None,
                 "outlier_reason": kind[3] if kind else ""}
        rec = synthesize(feed, rpm, cortex_mm=cortex, bone=bone_set, model=kind[0] if kind else "clogging",
                         mu_f=float(mu_f), mu_w=float(mu_w), u1_MPa=float(u1),
                         u2_MPa=float(bone_set.u2_MPa * u1 / bone_set.u1_MPa),
                         sample_rate_hz=sample_rate_hz, approach_s=float(rng.uniform(1.5, 3.0)),
                         tail_s=float(rng.uniform(1.5, 3.0)), effects=effects(rng),
                         seed=int(rng.integers(2**31)), specimen=f"synthetic {bone_set.name} femur",
                         metadata=extra)
        runs.append((f"{role}/f{feed:g}_N{rpm:g}_r{replicate:02d}.csv", rec))
    return runs


TRUTH_COLUMNS = ["file", "role", "feed_mm_s", "spindle_rpm", "replicate", "condition_mu_f", "condition_mu_w",
                 "true_mu_f", "true_mu_w", "true_initial_force_N", "true_growth_exponent", "cortex_mm",
                 "outlier", "outlier_reason"]


def write_dataset(folder, bone: str | BoneSet = "bovine", replicates: int = 10, outliers: int = 3, seed: int = 0,
                  sample_rate_hz: float = 1000.0, torque_unit: str = "Nmm", format: str | None = None) -> str:
    """Write a synthetic calibration data set (atomically, as a whole folder); return a summary.

    Parameters
    ----------
    folder : path-like
        Written as ``calibration/*.csv``, ``validation/*.csv`` (or the suffix of ``format``),
        ``truth.csv`` (per-run ground truth) and ``generating_bone_set.toml`` (the power law the
        runs were drawn around).
    bone : str or BoneSet
        The bone set the runs' friction is drawn around.
    replicates, outliers, seed : int
        Runs per condition, planted outlier runs, random seed.
    sample_rate_hz : float
    torque_unit : {"Nmm", "Nm"}
    format : str, optional
        One of a registered format (:func:`femstudy.recordings.formats.registry.writers`) (default: CSV).

    Returns
    -------
    str
        What was written and how to calibrate on it.

    Examples
    --------
    >>> print(write_dataset("demo", replicates=4))   # doctest: +SKIP
    """
    require(replicates >= 1, f"--replicates must be at least 1, got {replicates}")
    writer = registry.writer_for("recording.csv", format)  # an unknown format fails here, before any work
    bone_set = load_bone_set(bone) if isinstance(bone, str) else bone
    runs = dataset_recordings(bone_set, replicates=replicates, outliers=outliers, seed=seed,
                              sample_rate_hz=sample_rate_hz)
    truth = io.StringIO()
    truth_rows = csv.writer(truth, lineterminator="\n")
    truth_rows.writerow(TRUTH_COLUMNS)
    with atomic.atomic_folder(folder) as tmp:
        suffix = writer.suffix
        for k, (relative, rec) in enumerate(runs):
            relative = str(Path(relative).with_suffix(suffix))
            write_recording(tmp / relative, rec, torque_unit, format=writer.name)
            m = rec.metadata
            truth_rows.writerow([relative] + [m[c] if not isinstance(m[c], float) else f"{m[c]:.6g}"
                                          for c in TRUTH_COLUMNS[1:]])
            log.info("synthesised %d/%d runs", k + 1, len(runs), extra={"progress": ("runs", k + 1, len(runs))})
        atomic.write_text(tmp / "truth.csv", truth.getvalue())
        atomic.write_text(tmp / "generating_bone_set.toml", bone_set.to_toml())
    n_val = sum(r[0].startswith("validation") for r in runs)
    n_out = sum(bool(r[1].metadata["outlier"]) for r in runs)
    folder = Path(folder)
    return (f"wrote {folder}: {len(runs) - n_val} calibration runs ({len(CALIBRATION_CONDITIONS)} conditions x "
            f"{replicates}, {n_out} planted outliers) and {n_val} validation runs, drawn around bone set "
            f"'{bone_set.name}'; ground truth in {folder / 'truth.csv'}\n"
            f"calibrate with: femstudy calibrate {folder / 'calibration'} --validate {folder / 'validation'} "
            f"--name NAME")


def write_synthetic(path, *, format: str | None = None, time_unit: str = "s", force_unit: str = "N",
                    torque_unit: str = "Nmm", plot=None, **conditions) -> str:
    """Synthesise one recording, write it (and optionally its figure); return a summary line.

    Parameters
    ----------
    path : path-like
        The recording to write; the format comes from ``format``, else the suffix.
    format : str, optional
        One of a registered format (:func:`femstudy.recordings.formats.registry.writers`).
    time_unit, force_unit, torque_unit : str
        Units of the written columns (e.g. "ms", "kN", "N*m"); the values are converted.
    plot : path-like, optional
        Also draw the recording (.png, .pdf or .svg).
    **conditions
        Passed to :func:`~femstudy.recordings.synthetic.synthesize` (feed, speed, effects ...).

    Returns
    -------
    str
        What was written, with the ground truth (μ_f, μ_w, F_o) and the effects.

    Examples
    --------
    >>> print(write_synthetic("run.tdms", feed_mm_s=1.5, spindle_rpm=1500))   # doctest: +SKIP
    """
    from dataclasses import replace

    from femstudy.recordings.ranges import check_values

    require(plot is None or Path(plot).suffix.lower() in (".png", ".pdf", ".svg"),
            f"--plot must end in .png, .pdf or .svg, got '{plot}'")
    rec = synthesize(**conditions)
    check_values(replace(rec, source=str(path)), lambda row: f"sample {row + 1}", {},  # what no drill records
                 "the friction law or the energies are outside what the models describe here")
    write_recording(path, rec, torque_unit, format=format, time_unit=time_unit, force_unit=force_unit)
    m = rec.metadata
    summary = (f"wrote {path}: {rec.time_s.size} samples, {rec.duration_s:.2f} s; model {m['model']}, "
               f"mu_f = {m['true_mu_f']:.4f}, mu_w = {m['true_mu_w']:.4f}, F_o = {m['true_initial_force_N']:.2f} N; "
               f"effects: {', '.join(m['effects']) or 'none'}")
    if plot is not None:
        from femstudy.recordings.figures import plot_recording

        plot_recording(plot, replace(rec, source=str(path)))
        summary += f"\nwrote {plot}"
    return summary
