"""The files of an uncertainty run: uncertainty.json, uncertainty.csv (every sample), report.md
and the figures (histogram and CDF of each output; tornado of the Sobol indices or the rank
correlations), each written atomically."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.uncertainty.result import OUTPUTS

TITLES = {"max_deflection_mm": "max deflection [mm]", "drill_point_deflection_mm": "drill-point deflection [mm]",
          "hole_von_mises_MPa": "von Mises near the hole [MPa]",
          "hole_exclusion_von_mises_MPa": "von Mises outside the exclusion radius [MPa]",
          "governing_margin": "governing margin (strength ratio)"}


def write_results(result, folder: Path) -> tuple[str, ...]:
    """Write every file of ``result`` into ``folder``; returns their names."""
    folder.mkdir(parents=True, exist_ok=True)
    doc = result.to_json()
    atomic.write_text(folder / "uncertainty.json", json.dumps(doc, indent=1))
    rows = result.rows()
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    atomic.write_text(folder / "uncertainty.csv", buffer.getvalue())
    files = ["uncertainty.json", "uncertainty.csv"]
    for femur in result.femurs:
        files += write_figures(femur, folder)
    atomic.write_text(folder / "report.md", markdown(doc, files))
    return tuple(files + ["report.md"])


def write_figures(femur, folder: Path) -> list[str]:
    """``uncertainty-<case>-distributions.png`` and ``uncertainty-<case>-tornado.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    outputs = [o for o in OUTPUTS if np.isfinite(femur.samples[o]).sum() > 1]
    fig, axes = plt.subplots(2, len(outputs), figsize=(3.6 * len(outputs), 5.6), squeeze=False)
    for k, o in enumerate(outputs):
        x = np.sort(femur.samples[o][np.isfinite(femur.samples[o])])
        shown = np.percentile(x, [0.5, 99.5]) if x.size >= 200 else (x[0], x[-1])  # the tails' extremes: CSV
        axes[0, k].hist(x, bins=min(60, max(10, x.size // 20)), range=tuple(shown), color="tab:blue", alpha=0.8)
        axes[1, k].set_xlim(*shown)
        axes[0, k].set_title(TITLES[o], fontsize=9)
        axes[1, k].plot(x, np.arange(1, x.size + 1) / x.size, color="tab:blue")
        for q in (5, 50, 95):
            axes[1, k].axvline(np.percentile(x, q), color="grey", lw=0.8, ls="--")
        axes[1, k].set_xlabel(TITLES[o], fontsize=8)
        axes[1, k].set_ylabel("cumulative probability" if k == 0 else "")
        if o == "governing_margin":
            axes[1, k].axvline(1.0, color="tab:red", lw=1.2)
    fig.suptitle(f"{femur.name}: {len(femur.unit)} samples (dashed: 5, 50, 95 %; 0.5-99.5 % shown)", fontsize=10)
    fig.tight_layout()
    names = []
    path = folder / f"uncertainty-{femur.name}-distributions.png"
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    names.append(path.name)

    target = "max_deflection_mm"
    sens = femur.sensitivity.get(target) or {}
    if sens:
        inputs = list(sens)
        fig, ax = plt.subplots(figsize=(6.5, 0.45 * len(inputs) + 1.4))
        if isinstance(next(iter(sens.values())), dict):
            order = sorted(inputs, key=lambda n: sens[n]["ST"])
            y = np.arange(len(order))
            ax.barh(y + 0.2, [sens[n]["ST"] for n in order], 0.4, xerr=[sens[n]["ST_conf"] for n in order],
                    label="total (ST)", color="tab:orange")
            ax.barh(y - 0.2, [sens[n]["S1"] for n in order], 0.4, xerr=[sens[n]["S1_conf"] for n in order],
                    label="first order (S1)", color="tab:blue")
            ax.set_xlabel("Sobol index of the max deflection (95 % intervals)")
            ax.legend(loc="lower right", fontsize=8)
        else:
            order = sorted(inputs, key=lambda n: abs(sens[n]))
            y = np.arange(len(order))
            ax.barh(y, [sens[n] for n in order], color=["tab:red" if sens[n] < 0 else "tab:blue" for n in order])
            ax.axvline(0, color="k", lw=0.8)
            ax.set_xlabel("Spearman rank correlation with the max deflection")
        ax.set_yticks(y, order, fontsize=8)
        ax.set_title(f"{femur.name}: what the max deflection's spread comes from", fontsize=10)
        fig.tight_layout()
        path = folder / f"uncertainty-{femur.name}-tornado.png"
        with atomic.atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
        plt.close(fig)
        names.append(path.name)
    return names


def _fmt(x) -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.4g}"


def _stats_table(summary: dict) -> list[str]:
    lines = ["| output | mean | SD | 5 % | 50 % | 95 % | n |", "|---|---|---|---|---|---|---|"]
    for o in OUTPUTS:
        s = summary.get(o)
        if s:
            lines.append(f"| {o} | {_fmt(s['mean'])} | {_fmt(s['sd'])} | {_fmt(s['p5'])} | {_fmt(s['p50'])} | "
                         f"{_fmt(s['p95'])} | {s['n']} |")
    p = summary.get("P(governing_margin < 1)")
    if p:
        lines.append("")
        lines.append(f"P(governing margin < 1) = {p['probability']:.3g} ({p['below']} of {p['n']} hole samples; "
                     f"Wilson 95 % interval {p['wilson95'][0]:.3g}-{p['wilson95'][1]:.3g})")
    return lines


def markdown(doc: dict, files: list[str]) -> str:
    """report.md: the uncertainty section (inputs and sources, distributions, sensitivities)."""
    lines = ["# Uncertainty", "", f"Method: {doc['method']}, {doc['samples']} "
             f"{'base ' if doc['method'] == 'sobol' else ''}samples per case; "
             f"run on {doc['execution']['scheduler']} with {doc['execution']['workers']} worker(s) "
             f"in {doc['execution']['wall_s']:.1f} s (docs/uncertainty.md).", ""]
    for f in doc["femurs"]:
        lines += [f"## {f['case']} ({f['surface']})", "", f"{f['evaluations']} evaluations.", "",
                  "| input | distribution | source |", "|---|---|---|"]
        lines += [f"| {n} | {d['description']} | {d['source']} |" for n, d in f["inputs"].items()]
        lines += ["", *_stats_table(f["summary"]), ""]
        nominal = f["nominal"]
        lines.append("Nominal inputs: " + ", ".join(f"{o} {_fmt(nominal.get(o))}" for o in OUTPUTS) + ".")
        if f["margin_basis"]:
            lines.append(f"Governing margin over {f['margin_basis']}.")
        if f["reduced_basis"]:
            r = f["reduced_basis"]
            lines.append(f"Stiffness samples: reduced bases of {r['clamped_sets']} clamped set(s), {r['snapshots']} "
                         f"snapshots ({r['basis_vectors']} vectors, {r['factorisations']} factorisations); largest "
                         f"energy-norm error bound {r['largest_energy_error_bound']:.2g} of the response, drill-point "
                         f"deflection within {r['largest_drill_point_bound_mm']:.2g} mm; {r['solved_directly']} "
                         "sample(s) solved directly.")
        lines.append("")
        sens = f["sensitivity"].get("max_deflection_mm") or {}
        if sens and isinstance(next(iter(sens.values())), dict):
            lines += ["Sobol indices of the max deflection (95 % intervals):", "",
                      "| input | S1 | ST |", "|---|---|---|"]
            lines += [f"| {n} | {s['S1']:.3f} ± {s['S1_conf']:.3f} | {s['ST']:.3f} ± {s['ST_conf']:.3f} |"
                      for n, s in sorted(sens.items(), key=lambda kv: -kv[1]["ST"])]
        elif sens:
            lines += ["Spearman rank correlation with the max deflection: " + ", ".join(
                f"{n} {v:+.2f}" for n, v in sorted(sens.items(), key=lambda kv: -abs(kv[1]))) + "."]
        lines.append("")
        lines += [f"![{name}]({name})" for name in files if name.startswith(f"uncertainty-{f['case']}-")]
        lines.append("")
    if doc.get("pooled"):
        lines += ["## Pooled over the cases", "", *_stats_table(doc["pooled"]), ""]
    return "\n".join(lines)
