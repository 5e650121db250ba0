"""The hole-based stresses in ``report.md`` and the study table, rendered from ``summary.json``
(its "hole" entry: :meth:`femstudy.hole.study.HoleResult.to_json`, the verification of
:mod:`femstudy.study.verification` and the margins of :mod:`femstudy.study.verdicts`)."""

from __future__ import annotations

import math


def _fmt(value, digits: int = 4) -> str:
    return "–" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}g}"


def _found(hole: dict, kind: str, radius_mm: float, quantity: str = "von_mises_MPa", loading: str = "dynamic"):
    verification = hole.get("verification") or {"measures": []}
    for m in verification["measures"]:
        if (m["kind"], m["quantity"], m.get("loading", "dynamic")) == (kind, quantity, loading) \
                and abs(m["radius_mm"] - radius_mm) < 1e-9:
            return m
    return None


def _verdict(hole: dict, kind: str, radius_mm: float, quantity: str = "von_mises_MPa",
             loading: str = "dynamic") -> str:
    """A measure's verdict measured in this run, with its relative uncertainty [%]."""
    m = _found(hole, kind, radius_mm, quantity, loading)
    if m is None:
        return "not verified"
    u = m["uncertainty"]
    return m["verdict"] + (f" (±{100 * u:.2g} %)" if u is not None and math.isfinite(u) else "")


def _where(margin: dict) -> str:
    radius = margin["radius_mm"]
    return {"distance": f"{radius:g} mm from the hole", "wall": f"{radius:g} mm beside the wall",
            "exclusion": f"beyond {radius:g} mm of the hole"}[margin["kind"]]


def _band(row: dict) -> str:
    low, high = row.get("band") or (None, None)
    if low is None:
        return "–"
    if not (math.isfinite(low) and math.isfinite(high)):
        return "not established"
    return f"{low:.3g}–{high:.3g}"


def governing_sentence(margins: dict, loading: str = "dynamic") -> str:
    """The governing margin as a sentence: the smallest margin of every near-hole measure, with
    the verdict and band of its measure, or why none can be quoted."""
    row = margins.get(f"governing_{loading}")
    if row is None:
        return "Governing margin: none, no near-hole measure has points in bone."
    criterion = "strain criterion" if row.get("governed_by") == "strain" else "stress criterion"
    status = row.get("status", "not verified")
    if status == "converged":
        how = f"converged (±{100 * row['uncertainty']:.2g} %)"
    elif status == "band":
        how = f"{row['convergence']}: band {_band(row)}"
    elif status == "not established":
        how = "not established: its measure's uncertainty could not be bounded"
    else:
        how = "not verified in this run"
    return (f"Governing margin ({loading} loading): {_fmt(row['margin'], 3)}, {_where(row)} at tip depth "
            f"{row['tip_depth_mm']:.2f} mm, by the {criterion} — {how}.")


def hole_table_rows(hole: dict) -> list[str]:
    """Rows of the run report's main table: von Mises at the headline distance from the hole
    wall and outside the quoted exclusion radius, dynamic, static and their ratio, each with its
    verdict (no thesis value: the thesis's stresses are point-load peaks)."""
    options = hole["options"]
    picks = [("distance", options["headline_distance_mm"], "von Mises {r:g} mm from the hole wall [MPa]"),
             ("exclusion", options["exclusion_radius_mm"], "max von Mises beyond {r:g} mm of the hole wall [MPa]")]
    lines = []
    for kind, radius, label in picks:
        row = next(r for r in hole[kind] if abs(r["radius_mm"] - radius) < 1e-9)
        d, s = row["dynamic"], row["static"]
        lines.append(f"| {label.format(r=radius)}, {_verdict(hole, kind, radius)} | {_fmt(d['von_mises_MPa'])} "
                     f"(tip {d['tip_depth_mm']:.2f} mm) | {_fmt(s['von_mises_MPa'])} | "
                     f"{_fmt(row['ratio_dynamic_to_static'], 3)} | – | – | – |")
    return lines


def _ligament(hole: dict) -> str:
    """The bone left ahead of the deepest tip on the drill axis, as a sentence (empty when the
    local model is solid bone to its depth cap)."""
    bottom = hole.get("axis_bottom_mm")
    if bottom is None:
        return ""
    deepest = hole["stations"][-1]["tip_depth_mm"]
    return (f" On the drill axis the bone ends {bottom:.2f} mm below the entry point; the deepest tip leaves "
            f"a {bottom - deepest:.2f} mm ligament.")


def _axis(hole: dict) -> str:
    evidence = hole.get("bone_axis_evidence") or {}
    if evidence.get("axis") == "local":
        return (f" The cortex's material and strength axis is the bone's local axis at the site "
                f"({evidence.get('angle_to_long_axis_deg', 0):.1f}° from the femur's long axis; {evidence['why']}).")
    if evidence:
        return f" The cortex's material and strength axis is the femur's long axis ({evidence.get('why', '')})."
    return ""


def verification_lines(hole: dict) -> list[str]:
    """How the near-hole measures were verified on this femur and mesh (in this run, or by an earlier
    run of the same inputs and code), and what it cost."""
    v = hole.get("verification")
    if not v:
        return ["The near-hole measures were not verified in this run (loads.verify = false): their values carry "
                "no verdict and the margins no band.", ""]
    if v.get("not_made"):
        return [f"**The near-hole measures could not be verified in this run**: {v['not_made']}. Their values carry "
                "no verdict and the margins no band.", ""]
    levels = ", ".join(f"{f:.3g}" for f in v["levels"])
    dofs = ", ".join(f"{d:,}" for d in v["dofs"])
    made = ("**Verification, made by an earlier run of the same inputs and code and read back by this one** "
            "(docs/failure.md; docs/solver.md, kept answers)" if v.get("kept_from_earlier_run") else
            "**Verification in this run** (docs/failure.md)")
    return [f"{made}: every measure below was judged on this femur and "
            f"mesh by refining the hole models (refinements {levels}, wall elements "
            + ", ".join(f"{h:.3g}" for h in v["measures"][0]["h_mm"]) + " mm; "
            f"{dofs} DOFs; the coarser and finer levels at stations {', '.join(str(s) for s in v['stations'])}, "
            f"where the measures peak) and by {len(v['replicates_deg'])} placements of the coarser "
            f"refinement (the mesh turned by " + ", ".join(f"{a:.3g}" for a in v["replicates_deg"])
            + " degrees) for the discretisation noise; verdicts of the convergence assessment with formal order "
            f"{v['formal_order']:g} (docs/convergence.md). {cost_sentence(v, 'Verification cost')}", ""]


def cost_sentence(part: dict, what: str) -> str:
    """What a part of the study cost [s], or that this run read it from an earlier one
    (femstudy.kept_answers)."""
    if part.get("kept_from_earlier_run"):
        return (f"{what} {part['seconds']:.1f} s when computed; this run read it, kept from an earlier run of the "
                "same inputs and code.")
    return f"{what} {part['seconds']:.1f} s."


def hole_section(hole: dict) -> list[str]:
    """The hole's stations, the stresses at each distance from the wall, the exclusion-radius
    sensitivity and the failure margins, as Markdown lines."""
    options = hole["options"]
    lines = ["**Stresses near the drilled hole** (docs/hole.md): the global model drives local models of the "
             f"hole at {len(hole['stations'])} depth station{'s' if len(hole['stations']) != 1 else ''} (radius "
             f"{options['submodel_radius_mm']:g} mm, refinement {options['refinement']:.3g}, cutting loads spread "
             f"over the drill-point cone as '{options.get('cone_traction', 'uniform')}'); cutting thrust and torque "
             "on the drill-point cone, chip evacuation torque as wall friction and its thrust on the bottom. The "
             "hole's geometry is read off the bone's surfaces, not the global mesh. Maxima over the stations and "
             "over every point at the stated distance from the hole surface (wall and cone; the last column: the "
             "points beside the cylindrical wall only), each with its verdict and uncertainty measured on this femur "
             f"and mesh.{_ligament(hole)}{_axis(hole)}", ""]
    lines += verification_lines(hole)
    lines += ["| station | tip depth [mm] | time [s] | cutting thrust [N] | cutting torque [N·mm] | evacuation thrust [N] "
              "| evacuation torque [N·mm] | DOFs | time [s] |", "|---|---|---|---|---|---|---|---|---|"]
    for s in hole["stations"]:
        lines.append(f"| {s['station']} | {s['tip_depth_mm']:.2f} | {s['time_s']:.2f} | {s['cutting_thrust_N']:.1f} | "
                     f"{s['cutting_torque_Nmm']:.1f} | {s['evacuation_thrust_N']:.1f} | {s['evacuation_torque_Nmm']:.1f} | "
                     f"{s['dofs']:,} | {s['seconds']:.1f} |")
    lines += ["", "| distance from the hole [mm] | von Mises dynamic [MPa] | at tip depth [mm] | max principal stress "
              "[MPa] | min principal stress [MPa] | max principal strain [µε] | min principal strain [µε] | "
              "von Mises static [MPa] | ratio | verdict | beside the wall: von Mises dynamic [MPa] | its "
              "verdict |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    wall = {r["radius_mm"]: r for r in hole.get("wall", [])}
    for row in hole["distance"]:
        d = row["dynamic"]
        beside = wall.get(row["radius_mm"], {}).get("dynamic", {}).get("von_mises_MPa")
        lines.append(f"| {row['radius_mm']:g} | {_fmt(d['von_mises_MPa'])} | {d['tip_depth_mm']:.2f} | "
                     f"{_fmt(d['max_principal_stress_MPa'])} | {_fmt(d['min_principal_stress_MPa'])} | "
                     f"{1e6 * d['max_principal_strain']:.0f} | {1e6 * d['min_principal_strain']:.0f} | "
                     f"{_fmt(row['static']['von_mises_MPa'])} | {_fmt(row['ratio_dynamic_to_static'], 3)} | "
                     f"{_verdict(hole, 'distance', row['radius_mm'])} | {_fmt(beside)} | "
                     f"{_verdict(hole, 'wall', row['radius_mm']) if beside is not None else '–'} |")
    lines += ["", f"Exclusion-radius sensitivity (maximum von Mises farther than the radius from the hole surface, "
                  f"excluding {options['cut_margin_mm']:g} mm at the local model's cut boundary and the clamp zones; "
                  f"quoted radius {options['exclusion_radius_mm']:g} mm):", "",
              "| exclusion radius [mm] | von Mises dynamic [MPa] | at [mm] (x, y, z) | its distance from the hole [mm] "
              "| von Mises static [MPa] | ratio | verdict |", "|---|---|---|---|---|---|---|"]
    for row in hole["exclusion"]:
        d = row["dynamic"]
        where = ", ".join(f"{d[f'location_{a}_mm']:.1f}" for a in "xyz")
        lines.append(f"| {row['radius_mm']:g} | {_fmt(d['von_mises_MPa'])} | ({where}) | {d['location_distance_mm']:.2f} | "
                     f"{_fmt(row['static']['von_mises_MPa'])} | {_fmt(row['ratio_dynamic_to_static'], 3)} | "
                     f"{_verdict(hole, 'exclusion', row['radius_mm'])} |")
    lines += [""] + margin_lines(hole["margins"])
    return lines


def margin_lines(margins: dict) -> list[str]:
    """The margins to failure of every near-hole measure and the governing one."""
    static = {(r["kind"], r["radius_mm"]): r for r in margins["static"]}
    lines = [f"**Margin to failure** near the hole: the smallest load factor to failure over the stations, by the "
             f"stress criteria ({margins['criterion']}) and the cortical strain criterion ({margins['strain_limits']}); "
             f"{margins['source']}. Every measure counts: the governing margin is the smallest of all, quoted with "
             "the band its verification measured; a measure that has not converged is not dropped, its band is "
             "printed beside it.", "",
             "| where | margin, dynamic | governed by | stress criterion | strain criterion | at tip depth [mm] | "
             "verdict | band | margin, static |", "|---|---|---|---|---|---|---|---|---|"]
    for r in margins["dynamic"]:
        s = static.get((r["kind"], r["radius_mm"]))
        verdict = r.get("convergence") or "not verified"
        u = r.get("uncertainty")
        if u is not None and math.isfinite(u):
            verdict += f" (±{100 * u:.2g} %)"
        lines.append(f"| {_where(r)} | {_fmt(r['margin'], 3)} | {r['governed_by']} | {_fmt(r['strength_ratio'], 3)} | "
                     f"{_fmt(r['strain_ratio'], 3)} | {r['tip_depth_mm']:.2f} | {verdict} | {_band(r)} | "
                     f"{_fmt(s['margin'] if s else None, 3)} |")
    return lines + ["", governing_sentence(margins, "dynamic"), "", governing_sentence(margins, "static")]


def hole_headline_cell(summary: dict) -> str:
    """The study table's cell: the dynamic von Mises stress [MPa] at the headline distance from
    the hole wall, with that distance; "–" without a hole result."""
    hole = summary.get("hole")
    if not hole:
        return "–"
    return f"{_fmt(hole['headline']['dynamic']['von_mises_MPa'])} ({hole['headline']['distance_mm']:g} mm)"
