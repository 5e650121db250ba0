"""The hole-based stresses in ``report.md`` and the study table, rendered from ``summary.json``
(its "hole" entry, :meth:`femstudy.hole.study.HoleResult.to_json`)."""

from __future__ import annotations

from femstudy.study.verdicts import verdict_of


def _fmt(value, digits: int = 4) -> str:
    return "–" if value is None else f"{value:.{digits}g}"


def _verdict(hole: dict, kind: str, radius_mm: float) -> str:
    """A measure's convergence verdict at this run's mesh, with its uncertainty [%]."""
    m = verdict_of(hole.get("convergence", {"measures": []}), kind, radius_mm)
    return m["verdict"] + (f" ({100 * m['gci_fine']:.2g} %)" if m["gci_fine"] is not None else "")


def _where(margin: dict) -> str:
    radius = margin["radius_mm"]
    return f"{radius:g} mm from the hole" if margin["kind"] == "distance" else f"beyond {radius:g} mm of the hole"


def hole_table_rows(hole: dict) -> list[str]:
    """Rows of the run report's main table: von Mises at the headline distance from the hole
    wall and outside the quoted exclusion radius, dynamic, static and their ratio, each with its
    convergence verdict (no thesis value: the thesis's stresses are point-load peaks)."""
    options = hole["options"]
    picks = [("distance", options["headline_distance_mm"], "von Mises {r:g} mm from the hole wall [MPa]"),
             ("exclusion", options["exclusion_radius_mm"], "max von Mises beyond {r:g} mm of the hole wall [MPa]")]
    lines = []
    for kind, radius, label in picks:
        row = next(r for r in hole[kind] if abs(r["radius_mm"] - radius) < 1e-9)
        d, s = row["dynamic"], row["static"]
        lines.append(f"| {label.format(r=radius)}, {_verdict(hole, kind, radius)} | {_fmt(d['von_mises_MPa'])} (tip {d['tip_depth_mm']:.2f} mm) | "
                     f"{_fmt(s['von_mises_MPa'])} | {_fmt(row['ratio_dynamic_to_static'], 3)} | – | – | – |")
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


def hole_section(hole: dict) -> list[str]:
    """The hole's stations, the stresses at each distance from the wall, the exclusion-radius
    sensitivity and the failure margins, as Markdown lines."""
    options = hole["options"]
    source = hole.get("convergence", {}).get("source", "not assessed")
    lines = ["**Stresses near the drilled hole** (docs/hole.md): the global model drives local models of the "
             f"hole at {len(hole['stations'])} depth station{'s' if len(hole['stations']) != 1 else ''} (radius {options['submodel_radius_mm']:g} mm, "
             f"refinement {options['refinement']:g}); cutting thrust and torque on the drill-point cone, chip "
             "evacuation torque as wall friction and its thrust on the bottom. Maxima over the stations and over "
             "every point at the stated distance from the hole surface (wall and cone; the last column: the points "
             "beside the cylindrical wall only). The convergence column is each measure's verdict under refinement "
             f"of the hole model at this mesh (verdicts: {source}; docs/failure.md).{_ligament(hole)}", "",
             "| station | tip depth [mm] | time [s] | cutting thrust [N] | cutting torque [N·mm] | evacuation thrust [N] "
             "| evacuation torque [N·mm] | DOFs | time [s] |", "|---|---|---|---|---|---|---|---|---|"]
    for s in hole["stations"]:
        lines.append(f"| {s['station']} | {s['tip_depth_mm']:.2f} | {s['time_s']:.2f} | {s['cutting_thrust_N']:.1f} | "
                     f"{s['cutting_torque_Nmm']:.1f} | {s['evacuation_thrust_N']:.1f} | {s['evacuation_torque_Nmm']:.1f} | "
                     f"{s['dofs']:,} | {s['seconds']:.1f} |")
    lines += ["", "| distance from the hole [mm] | von Mises dynamic [MPa] | at tip depth [mm] | max principal stress "
              "[MPa] | min principal stress [MPa] | max principal strain [µε] | min principal strain [µε] | "
              "von Mises static [MPa] | ratio | convergence | beside the wall: von Mises dynamic [MPa] | its "
              "convergence |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
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
              "| von Mises static [MPa] | ratio | convergence |", "|---|---|---|---|---|---|---|"]
    for row in hole["exclusion"]:
        d = row["dynamic"]
        where = ", ".join(f"{d[f'location_{a}_mm']:.1f}" for a in "xyz")
        lines.append(f"| {row['radius_mm']:g} | {_fmt(d['von_mises_MPa'])} | ({where}) | {d['location_distance_mm']:.2f} | "
                     f"{_fmt(row['static']['von_mises_MPa'])} | {_fmt(row['ratio_dynamic_to_static'], 3)} | "
                     f"{_verdict(hole, 'exclusion', row['radius_mm'])} |")
    margins = hole["margins"]
    static = {(r["kind"], r["radius_mm"]): r for r in margins["static"]}
    lines += ["", f"**Margin to failure** near the hole: the smallest load factor to failure over the stations "
                  f"({margins['criterion']}; {margins['source']}). The stress under the load itself is not used, "
                  "and a measure whose convergence is not \"converged\" governs no margin "
                  f"(verdicts: {margins.get('convergence_source', 'not assessed')}).", "",
              "| where | strength ratio, dynamic | at tip depth [mm] | strength ratio, static | convergence |",
              "|---|---|---|---|---|"]
    for r in margins["dynamic"]:
        s = static.get((r["kind"], r["radius_mm"]))
        lines.append(f"| {_where(r)} | {_fmt(r['strength_ratio'], 3)} | {r['tip_depth_mm']:.2f} | "
                     f"{_fmt(s['strength_ratio'] if s else None, 3)} | {_verdict(hole, r['kind'], r['radius_mm'])} |")
    governing = margins.get("governing_dynamic")
    lines += ["", f"Governing margin (converged measures only): {_fmt(governing['strength_ratio'], 3)}, "
                  f"{_where(governing)}."
              if governing else "Governing margin: none quoted, no measure has a \"converged\" verdict for this run."]
    return lines


def hole_headline_cell(summary: dict) -> str:
    """The study table's cell: the dynamic von Mises stress [MPa] at the headline distance from
    the hole wall, with that distance; "–" without a hole result."""
    hole = summary.get("hole")
    if not hole:
        return "–"
    return f"{_fmt(hole['headline']['dynamic']['von_mises_MPa'])} ({hole['headline']['distance_mm']:g} mm)"
