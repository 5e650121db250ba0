"""Tables, convergence verdicts and plots of a sweep."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from femstudy import atomic
from femstudy.convergence import assess, coarsest_meeting_target

MESH_COLUMNS = ["point", "size_mm", "order", "refine", "site_size_mm", "envelope", "nodes", "elements", "dofs", "h_rep_mm",
                "max_deflection_mm", "drill_point_deflection_mm", "max_von_mises_MPa",
                "max_von_mises_excl_MPa", "hole_h_mm", "hole_von_mises_0.5mm_MPa", "hole_von_mises_1mm_MPa",
                "hole_von_mises_2mm_MPa", "hole_von_mises_5mm_MPa", "hole_von_mises_excl_MPa", "mesh_s", "tetwild_s",
                "mesh_cache_hit", "assembly_s", "solve_s", "hole_s"]
#: quantity -> (formal order for P1, for P2, singular in the continuum?, local?). A local
#: quantity's mesh measure is the drill site's element size, a global one's (V/N)^(1/3). The
#: "hole" ones (the largest von Mises stress at 0.5/1/2/5 mm from the hole wall and beyond the
#: quoted exclusion radius, docs/hole.md) keep their local models' refinement at every size, so
#: the ladder measures what the global mesh does to them: their measure is the site's.
QUANTITIES = {"max_deflection_mm": (2, 3, False, False), "drill_point_deflection_mm": (2, 3, False, False),
              "max_von_mises_MPa": (1, 2, True, True), "max_von_mises_excl_MPa": (1, 2, False, False),
              **{f"hole_von_mises_{d}mm_MPa": (1, 2, False, "hole") for d in ("0.5", "1", "2", "5")},
              "hole_von_mises_excl_MPa": (1, 2, False, "hole")}


def table_csv(rows: list[dict], columns: list[str]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
    return buf.getvalue()


def table_markdown(rows: list[dict], columns: list[str]) -> str:
    def cell(v):
        if v is None:
            return "–"
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(cell(r.get(c)) for c in columns) + " |" for r in rows]
    return "\n".join(lines)


def groups(rows: list[dict]) -> dict[tuple, list[dict]]:
    """Mesh rows grouped by (order, refine), each sorted fine to coarse; a size met twice (the
    remeshed point) is kept once."""
    out: dict[tuple, list[dict]] = {}
    for row in rows:
        group = out.setdefault((row["order"], row["refine"]), [])
        if all(r["size_mm"] != row["size_mm"] for r in group):
            group.append(row)
    return {k: sorted(v, key=lambda r: r["h_rep_mm"]) for k, v in sorted(out.items())}


def remeshing_noise(rows: list[dict], quantities) -> dict:
    """Per (order, refine) group and quantity, the relative range (max − min) / |mean| over the
    meshes of one size (the remeshed points and their original); 0 without replicates."""
    out: dict = {}
    for row in rows:
        group = out.setdefault(f"P{row['order']}-{row['refine']}", {q: 0.0 for q in quantities})
        same = [r for r in rows if r["order"] == row["order"] and r["refine"] == row["refine"]
                and r["size_mm"] == row["size_mm"]]
        if len(same) < 2:
            continue
        for q in quantities:
            values = [r.get(q) for r in same]
            if all(v is not None and np.isfinite(v) for v in values) and np.mean(values) != 0:
                group[q] = max(group[q], (max(values) - min(values)) / abs(float(np.mean(values))))
    return out


def mesh_measure(row: dict, local: bool) -> float:
    """The mesh size [mm] a quantity converges with: the site's element size for a local or hole
    one (when the site is refined), the representative (V/N)^(1/3) otherwise."""
    return row["site_size_mm"] if local and row.get("site_size_mm") else row["h_rep_mm"]


def convergence(rows: list[dict], target: float, quantities: dict = QUANTITIES) -> dict:
    """Per group and quantity: the assessment from the three finest meshes against the
    measured remeshing noise, and the coarsest global size whose max deflection is within
    ``target`` of the extrapolated value."""
    noise = remeshing_noise(rows, quantities)
    out = {}
    for (order, refine), group in groups(rows).items():
        name = f"P{order}-{refine}"
        entry = {"points": len(group), "quantities": {}, "remeshing_noise": noise.get(name, {})}
        if len(group) >= 3:
            for quantity, (p1, p2, singular, local) in quantities.items():
                values = [r.get(quantity) for r in group]
                if any(v is None or not np.isfinite(v) for v in values):
                    continue
                h = [mesh_measure(r, local) for r in group]
                a = assess(quantity, h, values, formal_order=p2 if order == 2 else p1, singular=singular,
                           noise=noise.get(name, {}).get(quantity, 0.0))
                entry["quantities"][quantity] = a.as_dict()
            deflection = entry["quantities"].get("max_deflection_mm")
            if deflection and deflection["verdict"] in ("converged", "converging"):
                # against the extrapolated value, or, where the convergence gives none (oscillatory,
                # within the noise), against the finest mesh's value
                extrapolated = deflection["extrapolated"]
                reference = extrapolated if extrapolated is not None else deflection["values"][0]
                best = coarsest_meeting_target([r["size_mm"] for r in group],
                                               [r["max_deflection_mm"] for r in group], reference, target)
                entry["recommended_size_mm"] = best[0] if best else None
                entry["recommended_error"] = best[1] if best else None
                entry["recommended_reference"] = "extrapolated" if extrapolated is not None else "finest"
        out[name] = entry
    return out


def convergence_markdown(assessment: dict, target: float) -> str:
    lines = []
    for name, entry in assessment.items():
        lines += [f"### {name}", ""]
        if not entry["quantities"]:
            lines += [f"{entry['points']} point(s): at least three are needed for an observed order.", ""]
            continue
        lines += ["| quantity | mesh measure h [mm] | finest values | remeshing noise | observed order | extrapolated "
                  "| GCI (fine) | verdict |", "|---|---|---|---|---|---|---|---|"]
        for q, a in entry["quantities"].items():
            order = "–" if a["observed_order"] is None else f"{a['observed_order']:.2f}"
            ext = "–" if a["extrapolated"] is None else f"{a['extrapolated']:.5g}"
            gci = "–" if a["gci_fine"] is None else f"{100 * a['gci_fine']:.2f} %"
            vals = ", ".join(f"{v:.5g}" for v in a["values"])
            hs = ", ".join(f"{x:.3g}" for x in a["h"])
            lines.append(f"| {q} | {hs} | {vals} | {100 * a['noise']:.2f} % | {order} | {ext} | {gci} | "
                         f"{a['verdict']}: {a['reason']} |")
        size = entry.get("recommended_size_mm")
        reference = {"extrapolated": "the extrapolated value", "finest": "the finest mesh's value (no "
                     "extrapolation: the values converge without a monotone order)"}.get(entry.get("recommended_reference"))
        if reference is None:
            line = "No size is recommended: the max deflection has not converged on these meshes."
        elif size:
            line = (f"Recommended global size: **{size:g} mm** (max deflection within "
                    f"{100 * entry['recommended_error']:.2f} % of {reference}; target {100 * target:g} %).")
        else:
            line = f"No size in this sweep meets the {100 * target:g} % target on max deflection against {reference}."
        lines += ["", line, ""]
    return "\n".join(lines)


def plots(folder: Path, rows: list[dict], assessment: dict) -> list[str]:
    """quantity vs element size and vs DOFs (log scales), one line per (order, refine)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for x_key, x_label, name in (("size_mm", "global element size [mm]", "vs_size.png"),
                                 ("dofs", "degrees of freedom", "vs_dofs.png")):
        fig, axes = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
        for ax, quantity in zip(axes.ravel(), QUANTITIES):
            for (order, refine), group in groups(rows).items():
                pts = sorted((r[x_key], r[quantity]) for r in group if r[quantity] is not None)
                ax.plot(*zip(*pts), marker="o", label=f"P{order}, {refine}")
                verdict = assessment[f"P{order}-{refine}"]["quantities"].get(quantity, {})
                extrapolated = verdict.get("extrapolated")
                if extrapolated is not None and verdict.get("verdict") in ("converged", "converging"):
                    ax.axhline(extrapolated, ls=":", lw=1, color=ax.lines[-1].get_color())
            ax.set_xscale("log")
            if x_key == "size_mm":
                ax.invert_xaxis()
            ax.set_xlabel(x_label)
            ax.set_ylabel(quantity.replace("_mm", " [mm]").replace("_MPa", " [MPa]").replace("_", " "))
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
        fig.suptitle("Mesh convergence (dotted: Richardson-extrapolated value, where converging)")
        with atomic.atomic_path(folder / name) as tmp:
            fig.savefig(tmp, dpi=120, format="png")
        plt.close(fig)
        written.append(name)
    return written
