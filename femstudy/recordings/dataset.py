"""A synthetic calibration data set shaped like the thesis's (§4.1.1, §5.1–5.2).

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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.drilling.friction import BoneSet, load_bone_set
from femstudy.errors import require
from femstudy.recordings.reader import FORMAT_SUFFIXES, Recording, write_recording
from femstudy.recordings.synthetic import Effects, FeedPulsation, Noise, SensorDrift, SpindleRipple, synthesize

#: Table 4-1 calibration conditions and Table 5-3 validation conditions, (f [mm/s], N [rpm]).
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


def write_dataset(folder, bone: str = "bovine", replicates: int = 10, outliers: int = 3, seed: int = 0,
                  sample_rate_hz: float = 1000.0, torque_unit: str = "Nmm", format: str | None = None,
                  progress=None) -> str:
    """Write the data set (atomically, as a whole folder) and return a summary to print.

    Layout: ``calibration/*.csv``, ``validation/*.csv`` (or the suffix of ``format``, one of
    :data:`~femstudy.recordings.reader.WRITE_FORMATS`), ``truth.csv`` (per-run ground truth)
    and ``generating_bone_set.toml`` (the power law the runs were drawn around).
    """
    require(format is None or format in FORMAT_SUFFIXES,
            f"unknown recording format '{format}'; choose one of {', '.join(FORMAT_SUFFIXES)}")
    bone_set = load_bone_set(bone)
    runs = dataset_recordings(bone_set, replicates=replicates, outliers=outliers, seed=seed,
                              sample_rate_hz=sample_rate_hz)
    truth = io.StringIO()
    writer = csv.writer(truth, lineterminator="\n")
    writer.writerow(TRUTH_COLUMNS)
    with atomic.atomic_folder(folder) as tmp:
        suffix = FORMAT_SUFFIXES[format or "csv"]
        for k, (relative, rec) in enumerate(runs):
            relative = str(Path(relative).with_suffix(suffix))
            write_recording(tmp / relative, rec, torque_unit, format=format or "csv")
            m = rec.metadata
            writer.writerow([relative] + [m[c] if not isinstance(m[c], float) else f"{m[c]:.6g}"
                                          for c in TRUTH_COLUMNS[1:]])
            if progress and (k + 1) % 10 == 0:
                progress(f"synthesised {k + 1}/{len(runs)} runs")
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
