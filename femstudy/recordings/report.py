"""Tables (text and CSV) of a calibration, and its comparison with the truth of synthetic runs."""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from femstudy.drilling.friction import BoneSet, evaluate_power_law
from femstudy.recordings.normality import format_normality
from femstudy.recordings.pipeline import CalibrationResult

ROLE_ORDER = {"calibration": 0, "held out": 1, "outlier": 2, "validation": 3}


def _csv(header: list[str], rows: list[list]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        writer.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in row])
    return buf.getvalue()


def _sorted_runs(result: CalibrationResult):
    return sorted(result.runs, key=lambda r: (ROLE_ORDER[r.role] == 3, r.condition, r.name))


RUN_COLUMNS = ["run", "role", "feed_mm_s", "spindle_rpm", "contact_s", "full_engagement_s", "cut_end_s", "cut_end",
               "initial_force_N", "growth_exponent_p", "mu_f", "mu_w", "r2_thrust", "r2_torque",
               "true_mu_f", "true_mu_w", "outlier_reason"]


def runs_csv(result: CalibrationResult) -> str:
    """Per run: cut times, Eq 4.8's F_o and p (the normality data), Eq 4.4's μ, own-fit R²."""
    rows = []
    for r in _sorted_runs(result):
        m = r.run.metadata
        rows.append([r.name, r.role, r.run.feed_mm_s, r.run.spindle_rpm, r.run.phase.contact_s,
                     r.run.phase.full_engagement_s, r.run.phase.end_s, r.run.phase.end_kind,
                     r.eq48_initial_force_N, r.eq48_growth_exponent, r.fit.mu_f, r.fit.mu_w, r.fit.r2_thrust[0],
                     r.fit.r2_torque[0], m.get("true_mu_f", ""), m.get("true_mu_w", ""), r.outlier_reason])
    return _csv(RUN_COLUMNS, rows)


def _sample_truth(result: CalibrationResult, cond, key: str) -> float | None:
    """Geometric mean of the runs' own true μ over the runs used for one condition."""
    used = set(next(c for c in result.conditions if (c.feed_mm_s, c.spindle_rpm) == cond).runs_used)
    values = [r.run.metadata.get(key) for r in result.runs if r.name in used]
    return float(np.exp(np.mean(np.log(values)))) if values and all(isinstance(v, float) for v in values) else None


def conditions_csv(result: CalibrationResult) -> str:
    rows = []
    for c in result.conditions:
        cond = (c.feed_mm_s, c.spindle_rpm)
        sd = [float(np.std(np.log(v), ddof=1)) if len(v) > 1 else "" for v in (c.per_run_mu_f, c.per_run_mu_w)]
        rows.append([c.feed_mm_s, c.spindle_rpm, len(c.runs_used), c.mu_f, c.mu_w, c.se_ln(c.per_run_mu_f),
                     c.se_ln(c.per_run_mu_w), sd[0], sd[1], c.growth_exponent, c.pooled.mu_f, c.pooled.mu_w,
                     c.true_mu_f if c.true_mu_f is not None else "", c.true_mu_w if c.true_mu_w is not None else "",
                     _sample_truth(result, cond, "true_mu_f") or "", _sample_truth(result, cond, "true_mu_w") or ""])
    return _csv(["feed_mm_s", "spindle_rpm", "runs", "mu_f", "mu_w", "se_ln_mu_f", "se_ln_mu_w", "sd_ln_mu_f_runs",
                 "sd_ln_mu_w_runs", "growth_exponent_p", "pooled_fit_mu_f", "pooled_fit_mu_w", "true_mu_f",
                 "true_mu_w", "sample_true_mu_f", "sample_true_mu_w"], rows)


def validation_csv(result: CalibrationResult) -> str:
    rows = []
    for r in result.by_role("held out", "validation"):
        v = r.validation
        rows.append([r.name, r.role, v.feed_mm_s, v.spindle_rpm, v.mu_f, v.mu_w, v.r2_thrust, v.r2_torque,
                     r.ann_r2[0] if r.ann_r2 else "", r.ann_r2[1] if r.ann_r2 else ""])
    return _csv(["run", "role", "feed_mm_s", "spindle_rpm", "mu_f", "mu_w", "r2_thrust", "r2_torque",
                 "ann_r2_thrust", "ann_r2_torque"], rows)


def ann_csv(result: CalibrationResult) -> str:
    s = result.ann
    return _csv(["hidden_neurons", "training_mse", "validation_mse"],
                [[n, a, b] for n, a, b in zip(s.neurons, s.training_mse, s.validation_mse)])


def truth_power_law(result: CalibrationResult) -> BoneSet | None:
    """The generating power law, from the conditions' true μ in synthetic headers (else None)."""
    truths = {}
    for r in result.runs:
        m = r.run.metadata
        if isinstance(m.get("condition_mu_f"), float) and isinstance(m.get("condition_mu_w"), float):
            truths[r.condition] = (m["condition_mu_f"], m["condition_mu_w"])
    if len(truths) < 4:
        return None
    conds = sorted(truths)
    try:
        return BoneSet(name="generating", feed_mm_s=tuple(c[0] for c in conds),
                       spindle_rpm=tuple(c[1] for c in conds), mu_f=tuple(truths[c][0] for c in conds),
                       mu_w=tuple(truths[c][1] for c in conds))
    except Exception:  # noqa: BLE001 - a degenerate truth table just means no comparison
        return None


def hull_deviation(bone: BoneSet, truth: BoneSet, steps: int = 41) -> tuple[float, float]:
    """Largest relative deviation of μ_f and μ_w from the truth inside the convex hull of the
    calibration conditions in (ln f, ln N), where the power law interpolates."""
    from scipy.spatial import Delaunay

    pts = np.column_stack([np.log(bone.feed_mm_s), np.log(bone.spindle_rpm)])
    f = np.exp(np.linspace(pts[:, 0].min(), pts[:, 0].max(), steps))
    n = np.exp(np.linspace(pts[:, 1].min(), pts[:, 1].max(), steps))
    F, N = (a.ravel() for a in np.meshgrid(f, n))
    inside = Delaunay(pts).find_simplex(np.column_stack([np.log(F), np.log(N)]), tol=1e-9) >= 0
    F, N = F[inside], N[inside]
    return tuple(float(np.max(np.abs(evaluate_power_law(mine, F, N) / evaluate_power_law(true, F, N) - 1)))
                 for mine, true in ((bone.a, truth.a), (bone.b, truth.b)))


def _truth_table(result: CalibrationResult, truth: BoneSet) -> list[str]:
    b = result.bone
    calib = [(c.feed_mm_s, c.spindle_rpm) for c in result.conditions]
    conds = calib + sorted({r.condition for r in result.by_role("validation")} - set(calib))
    lines = [f"  recovered vs generating law at  {'f mm/s':>7} {'N rpm':>6} {'mu_f':>7} {'true':>7} {'err':>7} "
             f"{'mu_w':>7} {'true':>7} {'err':>7}"]
    for f, n in conds:
        mf, mw = b.friction(f, n)
        tf, tw = truth.friction(f, n)
        where = "" if (f, n) in calib else "  (validation condition)"
        lines.append(f"  {'':<31}{f:>7.3g} {n:>6.0f} {mf:>7.4f} {tf:>7.4f} {100 * (mf / tf - 1):>+6.1f}% "
                     f"{mw:>7.4f} {tw:>7.4f} {100 * (mw / tw - 1):>+6.1f}%{where}")
    dev_f, dev_w = hull_deviation(b, truth)
    lines.append(f"  largest deviation inside the hull of the calibration conditions in (ln f, ln N): "
                 f"mu_f {100 * dev_f:.1f} %, mu_w {100 * dev_w:.1f} % (outside it the law extrapolates)")
    return lines


def summary_text(result: CalibrationResult, bone_path=None) -> str:
    """The printed report: runs, outliers, conditions, power law, validation, normality, ANN."""
    runs = result.runs
    n_cal = sum(r.role != "validation" for r in runs)
    drill = result.conditions[0].pooled.drill
    cutoffs = sorted({round(r.run.cutoff_hz, 3) for r in runs})
    out = [f"femstudy calibrate: {n_cal} calibration runs at {len(result.conditions)} conditions, "
           f"{len(result.by_role('validation'))} validation runs; drill D = {drill.diameter_mm:g} mm, "
           f"point angle {drill.point_angle_deg:g} deg",
           f"processing: cut isolated automatically (unless given), sensor drift removed, low-pass cut-off "
           f"{cutoffs[0]:g}-{cutoffs[-1]:g} Hz for figures (Table 4-4); Eq 4.4 fitted to the unfiltered cut", ""]
    truth = any("true_mu_f" in r.run.metadata for r in runs)
    out.append("Runs: friction of each run alone (Eq 4.4) and Eq 4.8's F_o and p")
    head = f"  {'run':<24} {'role':<11} {'f':>5} {'N':>6} {'contact':>8} {'end':>7} {'':<12} {'F_o':>6} " \
           f"{'p':>6} {'mu_f':>7} {'mu_w':>7} {'R2 F':>6} {'R2 T':>6}"
    out.append(head + (f" {'true mu_f':>9} {'true mu_w':>9}" if truth else ""))
    for r in _sorted_runs(result):
        ph, m = r.run.phase, r.run.metadata
        line = (f"  {r.name[:24]:<24} {r.role:<11} {r.run.feed_mm_s:>5.3g} {r.run.spindle_rpm:>6.0f} "
                f"{ph.contact_s:>8.3f} {ph.end_s:>7.3f} {ph.end_kind:<12} {r.eq48_initial_force_N:>6.2f} "
                f"{r.eq48_growth_exponent:>6.3f} {r.fit.mu_f:>7.4f} {r.fit.mu_w:>7.4f} {r.fit.r2_thrust[0]:>6.3f} "
                f"{r.fit.r2_torque[0]:>6.3f}")
        if truth:
            line += f" {m.get('true_mu_f', math.nan):>9.4f} {m.get('true_mu_w', math.nan):>9.4f}"
        out.append(line)
    outliers = result.by_role("outlier")
    out += ["", f"Outliers ({len(outliers)}; robust criterion: |ln mu - median| > 3.5 x max(1.4826 MAD, 0.1) "
                f"within the condition, or own-fit R2 < 0.5)"]
    out += [f"  {r.name}: {r.outlier_reason}" for r in outliers] or ["  none"]

    out += ["", "Conditions (Table 5-1): geometric mean of the used runs' friction, +- one standard error; "
                "'pooled' = one fit to all used runs"]
    head = (f"  {'f mm/s':>7} {'N rpm':>6} {'runs':>4} {'mu_f':>7} {'+-':>5} {'mu_w':>7} {'+-':>5} {'p':>6} "
            f"{'pooled mu_f':>11} {'pooled mu_w':>11}")
    with_truth = any(c.true_mu_f is not None for c in result.conditions)
    if with_truth:
        head += f" {'true mu_f':>9} {'err':>6} {'true mu_w':>9} {'err':>6} {'sample mu_f':>11} {'sample mu_w':>11}"
    out.append(head)
    for c in result.conditions:
        se_f, se_w = c.se_ln(c.per_run_mu_f), c.se_ln(c.per_run_mu_w)
        line = (f"  {c.feed_mm_s:>7.3g} {c.spindle_rpm:>6.0f} {len(c.runs_used):>4d} {c.mu_f:>7.4f} "
                f"{100 * se_f:>4.1f}% {c.mu_w:>7.4f} {100 * se_w:>4.1f}% {c.growth_exponent:>6.3f} "
                f"{c.pooled.mu_f:>11.4f} {c.pooled.mu_w:>11.4f}")
        if with_truth and c.true_mu_f is not None:
            cond = (c.feed_mm_s, c.spindle_rpm)
            line += (f" {c.true_mu_f:>9.4f} {100 * (c.mu_f / c.true_mu_f - 1):>+5.1f}% {c.true_mu_w:>9.4f} "
                     f"{100 * (c.mu_w / c.true_mu_w - 1):>+5.1f}% "
                     f"{_sample_truth(result, cond, 'true_mu_f') or math.nan:>11.4f} "
                     f"{_sample_truth(result, cond, 'true_mu_w') or math.nan:>11.4f}")
        out.append(line)
    if with_truth:
        out.append("  (true: the generating condition value; sample: geometric mean of the used runs' own true mu, "
                   "which scatter by the replicate spread)")
        errors = [(r.fit.mu_f / r.run.metadata["true_mu_f"] - 1, r.fit.mu_w / r.run.metadata["true_mu_w"] - 1)
                  for r in result.runs if r.role != "outlier" and isinstance(r.run.metadata.get("true_mu_f"), float)]
        if errors:
            e = np.array(errors)
            out.append(f"  per-run estimates against each run's own true mu ({len(e)} runs): mu_f rms "
                       f"{100 * np.sqrt(np.mean(e[:, 0] ** 2)):.1f} % (largest {100 * np.max(np.abs(e[:, 0])):.1f} %), "
                       f"mu_w rms {100 * np.sqrt(np.mean(e[:, 1] ** 2)):.1f} % "
                       f"(largest {100 * np.max(np.abs(e[:, 1])):.1f} %)")

    b = result.bone
    out += ["", "Power law ln mu = c0 + c1 ln f + c2 ln N + c3 ln f ln N (Eqs 4.5-4.7; Table 5-2)",
            "  a (mu_f): " + "  ".join(f"{x:+.4f}" for x in b.a),
            "  b (mu_w): " + "  ".join(f"{x:+.4f}" for x in b.b),
            f"  u1 = {b.u1_MPa:.1f} MPa (median over the used runs of F_o / (a sin(beta/2) tan(beta/2) l); "
            f"spread {np.std(result.u1_per_run_MPa, ddof=1) / np.mean(result.u1_per_run_MPa) * 100:.0f} %), "
            f"u2 = {b.u2_MPa:.1f} MPa (u1 x 7.56/133)"]
    true_law = truth_power_law(result)
    if true_law is not None:
        out.append("  generating law a: " + "  ".join(f"{x:+.4f}" for x in true_law.a)
                   + ";  b: " + "  ".join(f"{x:+.4f}" for x in true_law.b))
        out += _truth_table(result, true_law)
    held = result.by_role("held out", "validation")
    if held:
        out += ["", "Validation on held-out runs: model from the power law, only F_o and T_o fitted (Table 5-4); "
                    "ANN: best network of the neuron study"]
        out.append(f"  {'run':<24} {'role':<10} {'f':>5} {'N':>6} {'mu_f':>7} {'mu_w':>7} {'R2 force':>8} "
                   f"{'R2 torque':>9} {'ANN R2 F':>8} {'ANN R2 T':>8}")
        for r in held:
            v = r.validation
            ann_f, ann_t = r.ann_r2 if r.ann_r2 else (math.nan, math.nan)
            out.append(f"  {r.name[:24]:<24} {r.role:<10} {v.feed_mm_s:>5.3g} {v.spindle_rpm:>6.0f} {v.mu_f:>7.4f} "
                       f"{v.mu_w:>7.4f} {v.r2_thrust:>8.4f} {v.r2_torque:>9.4f} {ann_f:>8.4f} {ann_t:>8.4f}")
        out.append(f"  mean R2: force {np.mean([r.validation.r2_thrust for r in held]):.4f}, torque "
                   f"{np.mean([r.validation.r2_torque for r in held]):.4f}")
    if result.normality:
        out += ["", "Normality of F_o and p across replicates (values standardised within each condition, pooled; "
                    "Tables 4-2/4-3 method)"]
        for label, res in result.normality.items():
            out += [format_normality(res, f"  {label}"), ""]
    if result.ann is not None:
        s = result.ann
        out += ["Neural network (f, N, z -> F, T; tanh hidden layer, linear output, Levenberg-Marquardt): "
                "neuron study (Figs 5-12/5-13)",
                f"  {'neurons':>7} {'training MSE':>12} {'validation MSE':>14}"]
        out += [f"  {n:>7d} {a:>12.5f} {v:>14.5f}" for n, a, v in zip(s.neurons, s.training_mse, s.validation_mse)]
        out.append(f"  lowest validation error: {s.best.hidden} neuron(s)")
    corr = [r.fit.correlation for r in result.by_role("calibration")]
    out += ["", f"Identifiability: F_o is free per run, so the thrust fixes only p = eta M D/S; the torque's rise "
                f"relative to the thrust fixes mu_w, and mu_f follows from M. Correlation of the ln mu_f and ln mu_w "
                f"estimates within a run (Jacobian): median {np.median(corr):+.2f}"]
    out += [f"note: {n}" for n in result.notes]
    if bone_path:
        out += ["", f"saved bone set '{b.name}' to {bone_path} (use: femstudy loads --bone {b.name}; "
                    f"case files: [drilling] bone = \"{b.name}\")"]
    return "\n".join(out)
