"""What ``femstudy diagnose`` prints and writes: summary text, figures, markdown report.

Every function takes a :class:`~femstudy.diagnosis.result.Diagnosis` ``d`` and reads it through
``d.to_json()`` and its arrays; this module imports nothing of the diagnosis itself."""

from __future__ import annotations

import json
import math
import textwrap

import numpy as np

from femstudy import atomic
from femstudy.plotting import pyplot, save

UNITS = {"thrust_N": ("thrust", "N"), "torque_Nmm": ("torque", "N·mm")}
#: A calibration scale further than this from 1 is pointed out.
SCALE_NOTE = 0.02


def _wrap(text: str, indent: int) -> str:
    return textwrap.fill(text, width=100, initial_indent=" " * indent, subsequent_indent=" " * indent)


def summary_text(d) -> str:
    """The printed summary: inputs, noise, alignment, mismatch, mechanisms, unexplained
    features, fit (in-sample and held out), residual check. "Compared below" is the frequency
    where the smoothing's gain is exp(−1/2)."""
    rec, problem = d.recording, d.problem
    lines = [f"recording {rec.name}: {rec.duration_s:.2f} s at {rec.sample_rate_hz:.0f} Hz, "
             f"f = {rec.feed_mm_s:g} mm/s, N = {rec.spindle_rpm:g} rpm, cortex {problem.geometry.cortex_mm:.2f} mm; "
             f"simulation: {d.simulation_label}"]
    lines += [f"  note: {n}" for n in d.notes]
    noise = ", ".join(f"{UNITS[c][0]} {s:.3g} {UNITS[c][1]}" for c, s in zip(problem.channels, problem.sigma_raw))
    lines.append(f"noise: white part (spectrum above 10 Hz) {noise}; compared below "
                 f"{1 / (2 * math.pi * problem.band.sigma_s):.1f} Hz at {problem.band.t_dec.size} instants")
    js = d.to_json()
    for c, m in js["noise_model"].items():
        k = problem.channels.index(c)
        lines.append(f"  {UNITS[c][0]} noise fitted on {m['fitted_on']}: white + coloured, alpha {m['alpha']:.2f} above "
                     f"{m['corner_hz']:.3g} Hz; {float(np.median(problem.sigma[k])):.3g} {UNITS[c][1]} per compared sample")
    timing = js["timing"]
    events = ", ".join(f"{k[:-2].replace('_', ' ')} {v:.2f} s" for k, v in timing.items()
                       if k.endswith("_s") and isinstance(v, float))
    lines.append(f"timing (from the simulation, on the recording's clock): {events}")
    a = d.to_json()["alignment"]
    lines.append(f"alignment (not physics): shift {a['shift_s'] * 1e3:+.0f} ms, "
                 + ", ".join(f"{UNITS[c][0]} tare {a[f'{c}_tare']:+.3g} {UNITS[c][1]}" for c in problem.channels)
                 + (f", stop depth {a['stop_depth_mm']:.2f} mm" if "stop_depth_mm" in a else ""))
    scales = d.to_json()["calibration"]
    if problem.calibrate:
        lines.append("calibration (not physics): the simulated cutting loads rescaled, " + ", ".join(
            f"{UNITS[c][0]} x {scales[f'{c}_scale']:.4g}" for c in problem.channels))
    for c in problem.channels:
        g = scales[f"{c}_scale"]
        if abs(g - 1) > SCALE_NOTE:
            lines.append(f"  note: the simulated {UNITS[c][0]} is {100 * abs(1 / g - 1):.0f} % too "
                         f"{'high' if g < 1 else 'low'}: a calibration difference (specific cutting energy, "
                         f"drill), not missing physics")
    lines.append("")
    if js["mismatch"]:
        lines.append("mismatch (recording vs aligned simulation, beyond noise):")
        for m in js["mismatch"]:
            lines.append(f"  {m['channel']:11s} {m['start_s']:7.2f} - {m['end_s']:7.2f} s   "
                         f"-log10 p = {m['significance']:.4g}   max |z| = {m['max_abs_z']:.3g}")
    else:
        lines.append("mismatch: none beyond noise")
    lines.append("")
    if js["missing_physics"]:
        lines.append("missing physics:")
        for m in js["missing_physics"]:
            lines.append(f"  {m['mechanism']} (confidence {m['confidence']:.3f}, drop-one dBIC "
                         f"{m['evidence']['delta_bic']:.4g})")
            lines.append(_wrap(m["explanation"], 4))
    elif js["unexplained"]:
        lines.append("missing physics: none of the catalogue's mechanisms")
    else:
        lines.append("missing physics: none - the simulation explains the recording within the noise")
    if js["unexplained"]:
        lines += ["", "unexplained (outside the catalogue):"]
        for u in js["unexplained"]:
            lines.append(f"  {u['channel']:11s} {u['start_s']:7.2f} - {u['end_s']:7.2f} s   [{u['kind']}]")
            lines.append(_wrap(u["description"], 4))
    lines.append("")
    for s in d.fit_summary:
        name, unit = UNITS[s.channel]
        b, i = s.baseline, s.improved
        lines.append(f"fit, {name} over the cut {s.window_s[0]:.2f}-{s.window_s[1]:.2f} s: "
                     f"R2 {b.r2:.4f} -> {i.r2:.4f} in sample, {b.r2_heldout:.4f} -> {i.r2_heldout:.4f} "
                     f"held out; RMSE {b.rmse:.4g} -> {i.rmse:.4g} {unit}")
    check = js["residual_check"]
    if check["consistent_with_noise"]:
        verdict = "consistent with the noise model"
    elif js["unexplained"]:
        verdict = "NOT consistent with noise: see 'unexplained'"
    else:
        verdict = "NOT consistent with noise, though no feature stands out"
    lines.append(f"residual after the fit: chi2/dof = {check['chi2_per_dof']:.3g} ({verdict})")
    return "\n".join(lines)


def _shade(ax, d, channel: str) -> None:
    js = d.to_json()
    for m in js["mismatch"]:
        if m["channel"] == channel:
            ax.axvspan(m["start_s"], m["end_s"], color="tab:orange", alpha=0.12, lw=0)
    for u in js["unexplained"]:
        if u["channel"] in (channel, "both"):
            ax.axvspan(u["start_s"], u["end_s"], fill=False, hatch="//", edgecolor="tab:purple", alpha=0.35, lw=0)


def plot(path, d, panels: str = "both", channels: tuple[str, ...] | None = None) -> None:
    """Overlay (recording, simulation, simulation + missing physics) and/or the smoothed
    residual before and, on its own scale, after adding the missing physics, per channel
    (default all); mismatch intervals shaded."""
    plt = pyplot()
    problem, rec = d.problem, d.recording
    residuals = ("before", "after") if d.subset else ("before",)
    kinds = {"both": ("overlay",) + residuals, "overlay": ("overlay",), "residual": residuals}[panels]
    rows = [(c, k) for c in (channels or problem.channels) for k in kinds]
    heights = [1.5 if k == "overlay" else 1.0 for _, k in rows]
    fig, axes = plt.subplots(len(rows), 1, figsize=(9, 1.9 * sum(heights) + 0.8), sharex=True,
                             constrained_layout=True, squeeze=False, gridspec_kw={"height_ratios": heights})
    t_model, t_dec = problem.band.t_model, problem.band.t_dec
    js = d.to_json()
    base = dict(zip(problem.channels, d.baseline.evaluation.grid))
    improved = dict(zip(problem.channels, d.improved.evaluation.grid))
    found = ", ".join(m["mechanism"].replace("_", " ") for m in js["missing_physics"]) or "nothing missing"
    raw = {"thrust_N": rec.thrust_N, "torque_Nmm": rec.torque_Nmm}
    for ax, (c, kind) in zip(axes[:, 0], rows):
        k = problem.channels.index(c)
        name, unit = UNITS[c]
        _shade(ax, d, c)
        if kind == "overlay":
            ax.plot(rec.time_s, raw[c], color="0.75", lw=0.4, label="recording")
            ax.plot(t_dec, problem.y[k], "k.", ms=3, label="recording, smoothed")
            ax.plot(t_model, base[c], color="tab:blue", lw=1.2, ls="--", label="simulation")
            if d.subset:
                ax.plot(t_model, improved[c], color="tab:red", lw=1.2, label=f"+ {found}")
            ax.set_ylabel(f"{name} [{unit}]")
        else:
            fit, color, label = ((d.baseline, "tab:blue", "recording − simulation") if kind == "before" else
                                 (d.improved, "tab:red", "after adding the missing physics"))
            sd = 3 * problem.sigma[k]
            ax.fill_between(t_dec, -sd, sd, color="0.85", lw=0, label="±3σ noise")
            ax.plot(t_dec, problem.y[k] - fit.model[k], color=color, lw=1, marker=".", ms=3, label=label)
            ax.axhline(0, color="0.3", lw=0.6)
            ax.set_ylabel(f"{name} residual\n[{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best", framealpha=0.85)
    axes[-1, 0].set_xlabel("time [s]")
    extra = (f"; unexplained: {', '.join(sorted({u['kind'] for u in js['unexplained']}))} (hatched)"
             if js["unexplained"] else "")
    fig.suptitle(f"{rec.name}: {found}{extra} (shaded: mismatch beyond noise)", fontsize=10)
    save(fig, path)


def write_json(path, d) -> None:
    """The JSON contract (:meth:`Diagnosis.to_json`), written atomically."""
    atomic.write_text(path, json.dumps(d.to_json(), indent=2) + "\n")


def markdown(d, summary: str) -> str:
    """report.md: the summary, both figures, each mechanism's parameters and the best subsets."""
    js = d.to_json()
    lines = [f"# Diagnosis of {d.recording.name}", "", "```", summary, "```", "",
             "![overlay](overlay.png)", "", "![residuals](residuals.png)", "",
             "## Mechanisms", ""]
    if not js["missing_physics"]:
        lines.append("None: the simulation explains the recording within the noise.")
    for m in js["missing_physics"]:
        lines += [f"### {m['mechanism']} (confidence {m['confidence']:.3f})", "", m["explanation"], "",
                  "| parameter | value |", "|---|---|"]
        lines += [f"| {k} | {v} |" for k, v in m["parameters"].items()]
        lines.append("")
    if js["unexplained"]:
        lines += ["## Unexplained (outside the catalogue)", "", "| from [s] | to [s] | channel | kind | description |",
                  "|---|---|---|---|---|"]
        lines += [f"| {u['start_s']} | {u['end_s']} | {u['channel']} | {u['kind']} | {u['description']} |"
                  for u in js["unexplained"]]
        lines.append("")
    lines += ["## Candidate subsets (BIC, lowest first)", "", "| mechanisms | BIC |", "|---|---|"]
    lines += [f"| {s} | {b:.1f} |" for s, b in list(js["selection"]["bic"].items())[:8]]
    if js["selection"]["not_selected"]:
        lines += ["", "Considered and not kept:", ""]
        lines += [f"- {m}: {why}" for m, why in js["selection"]["not_selected"].items()]
    lines += ["", "Machine-readable: [diagnosis.json](diagnosis.json).", ""]
    return "\n".join(lines)


def write_report(folder, d, summary: str) -> None:
    """``folder``/report.md, overlay.png, residuals.png and diagnosis.json (written atomically)."""
    with atomic.atomic_folder(folder) as tmp:
        plot(tmp / "overlay.png", d, "overlay")
        plot(tmp / "residuals.png", d, "residual")
        write_json(tmp / "diagnosis.json", d)
        (tmp / "report.md").write_text(markdown(d, summary), encoding="utf-8")
