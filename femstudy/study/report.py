"""``report.md`` of one run and the combined table of several, both rendered from
``summary.json`` so a table can be rebuilt from finished results folders."""

from __future__ import annotations

import math

from femstudy.study.hole_report import cost_sentence, hole_headline_cell, hole_section, hole_table_rows
from femstudy.thesis import MAX_DEFLECTION_MM, MAX_VON_MISES_MPA

#: Site names that correspond to the thesis's three rows (§3.3.3: mid-diaphysis, proximal end, distal end).
#: Site name → the thesis row (Tables 5-14/5-15) it compares with. The thesis drilled the
#: proximal femur near the femoral neck and the distal femur near the knee (§3.3.3), so only
#: those sites compare with its proximal and distal rows; subtrochanteric and supracondylar
#: sites are femstudy's own and compare with no row.
THESIS_SITE = {"mid-diaphysis": "mid-diaphysis", "middiaphysis": "mid-diaphysis",
               "femoral neck": "proximal", "neck": "proximal", "proximal": "proximal",
               "lateral condyle": "distal", "knee": "distal", "distal": "distal"}


def _fmt(value, digits: int = 4) -> str:
    return "–" if value is None else f"{value:.{digits}g}"


def thesis_values(site_name: str):
    """Thesis Tables 5-14/5-15 (dynamic, static) for a site name, or None."""
    key = THESIS_SITE.get(site_name.lower())
    return (MAX_DEFLECTION_MM[key], MAX_VON_MISES_MPA[key]) if key else None


def out_of_range_banner(summary: dict) -> list[str]:
    """Lines that mark a study run with ``--force`` past failed plausibility gates
    (femstudy.study.plausibility), or none."""
    found = summary.get("out_of_range") or []
    if not found:
        return []
    return (["**OUT OF RANGE.** This study was run with `--force` past femstudy's plausibility checks "
             "(docs/checks.md); its numbers do not describe a drilled femur:", ""]
            + [f"- {f['check']}: {f['message']}" for f in found] + [""])


def femur_paragraph(summary: dict) -> str:
    """The user's bone as femstudy found it: the surface file, units and why, side, length, which
    end is proximal, anterior, what the case file set, and the drill site's cortex."""
    case, mesh, site = summary["case"], summary["mesh"], summary["site"]
    frame = summary.get("frame") or {}
    surface = case["geometry"]["surface"]
    name = "femstudy's built-in femur" if surface == "builtin" else f"`{surface}`"
    units = (frame.get("evidence") or {}).get("units") or {}
    overridden = frame.get("overridden") or []
    found = "all detected" if not overridden else "set in the case file: " + ", ".join(overridden)
    beyond = {"canal": "the medullary canal", "cancellous": "cancellous bone"}.get(site.get("beyond_cortex"), "–")
    return (f"Femur: {name}, a {frame.get('side', '?')} femur {mesh['length_mm']:.0f} mm long; units "
            f"{frame.get('units', '?')} (×{frame.get('scale_to_mm', 1):g} to mm: {units.get('why', 'not recorded')}); "
            f"proximal end {frame.get('evidence', {}).get('proximal_end', '?')} along the long axis "
            f"{_vector(frame.get('up'))}, anterior {_vector(frame.get('anterior'))} ({found}; summary.json "
            f"\"frame\" has the evidence). At the {site['name']} site the drill crosses "
            f"{site['cortical_thickness_mm']:.2f} mm of cortex into {beyond}.")


def _vector(v) -> str:
    return "–" if v is None else "(" + ", ".join(f"{float(c):.3f}" for c in v) + ")"


def run_report(summary: dict) -> str:
    """A short Markdown report a researcher can paste from."""
    case, mesh, site, load = summary["case"], summary["mesh"], summary["site"], summary["loading"]
    res, solver, dyn = summary["results"], summary["solver"], summary.get("dynamics", {})
    thesis = thesis_values(site["name"])
    excl = case["analysis"]["exclusion_radius_mm"]
    rows = [("maximum deflection [mm]", "max_deflection_mm", 0),
            ("deflection at the drill point [mm]", "drill_point_deflection_mm", None),
            ("maximum von Mises stress [MPa]", "max_von_mises_MPa", 1),
            (f"max von Mises outside {excl:g} mm of the patch [MPa]", "max_von_mises_excl_MPa", None)]
    hole = summary.get("hole")
    if hole:  # the patch's peak stress is mesh-dependent: the hole's measures replace it
        rows = rows[:2]
    lines = [f"# {case['name']}: drilling at the {site['name']} site", ""] + out_of_range_banner(summary) + [
             case.get("description", ""), "", femur_paragraph(summary), "",
             f"Mesh: {mesh['n_tets']:,} tetrahedra, "
             f"P{case['mesh']['order']} elements, {solver['dofs']:,} DOFs; both ends clamped over "
             f"{case['clamps']['length_mm']:g} mm. Drill Ø{case['drill']['diameter_mm']:g} mm at "
             f"f = {load['feed_mm_s']:g} mm/s, N = {load['spindle_rpm']:g} rpm, {load['depth_mm']:.2f} mm "
             f"unicortical ({load['bone_set']} friction: μ_f = {load['mu_f']:.4f}, μ_w = {load['mu_w']:.4f}).",
             "", "| quantity | dynamic | static Allotta | ratio | thesis dynamic | thesis static | thesis ratio |",
             "|---|---|---|---|---|---|---|"]
    for label, key, thesis_index in rows:
        r = res[key]
        t = thesis[thesis_index] if thesis and thesis_index is not None else None
        lines.append(f"| {label} | {_fmt(r['dynamic']['value'])} (t = {r['dynamic']['time_s']:.2f} s) | "
                     f"{_fmt(r['static']['value'])} | {_fmt(r['ratio_dynamic_to_static'], 3)} | "
                     f"{_fmt(t[0] if t else None)} | {_fmt(t[1] if t else None)} | "
                     f"{_fmt(t[0] / t[1] if t else None, 3)} |")
    lines += hole_table_rows(hole) if hole else []
    lines += ["", f"Peak loads: dynamic {load['peak_thrust_N']:.1f} N / {load['peak_torque_Nmm']:.1f} N·mm, "
                  f"static {load['static_thrust_N']:.1f} N / {load['static_torque_Nmm']:.1f} N·mm.", ""]
    if hole:
        lines += hole_section(hole)
    else:
        lines += ["**Margin to failure** (strength / peak von Mises under the dynamic loading; the peak under "
                  "the patch grows under mesh refinement, the one outside the exclusion zone is bounded; "
                  "docs/convergence.md gives the mesh sensitivity of both):", "",
                  "| region | peak von Mises [MPa] | strength [MPa] | safety factor |", "|---|---|---|---|"]
        for region, m in summary["margins"]["dynamic"].items():
            kind = "yield" if "yield_MPa" in m else "ultimate"
            lines.append(f"| {region} | {_fmt(m['peak_von_mises_MPa'])} | {m[kind + '_MPa']:g} ({kind}) | "
                         f"{_fmt(m['safety_factor_' + kind], 3)} |")
        outside = res["max_von_mises_excl_MPa"]["dynamic"]["value"]
        cortical = summary["margins"]["dynamic"].get("cortical", {})
        if cortical.get("yield_MPa") and outside:
            lines.append(f"| cortical, outside {excl:g} mm of the patch | {_fmt(outside)} | {cortical['yield_MPa']:g} "
                         f"(yield) | {_fmt(cortical['yield_MPa'] / outside, 3)} |")
    if summary.get("mesh_convergence"):
        lines += ["", mesh_convergence_line(summary["mesh_convergence"])]
    if summary.get("sensitivity"):
        lines += [""] + sensitivity_section(summary["sensitivity"])
    if dyn.get("frequencies_Hz"):
        lines += ["", dynamics_paragraph(dyn, case["time"]["step_s"])]
    lines += ["", f"Solved with {solver['linear_solver']} in {summary['timings']['total_s']:.1f} s "
                  f"(mesh {summary['timings']['mesh_s']:.1f} s"
                  f"{', cached' if mesh.get('cache_hit') else ''})."
                  + (f" Figures: {', '.join(figures)}." if (figures := summary.get('figures', {}).get('files')) else "")
                  + (f" Fields for ParaView: {' and '.join(fields)} (`femstudy view` shows them)."
                     if (fields := summary.get('figures', {}).get('fields')) else ""), ""]
    return "\n".join(lines)


def mesh_convergence_line(record: dict) -> str:
    """What a recorded sweep says of this run's answers under global refinement, or that none did."""
    found = record.get("quantities") or {}
    if not found:
        return f"**Global mesh convergence**: not assessed at {record['size_mm']:g} mm: {record['source']}."
    parts = [f"{_answer(q) if q in ANSWER_WORDS or q.startswith('von_mises') else q.replace('hole_', '').replace('_', ' ')}"
             f" {v['verdict']}" + (f" (±{100 * v['uncertainty']:.2g} %)" if v.get("uncertainty") is not None else "")
             for q, v in found.items()]
    return (f"**Global mesh convergence** at {record['size_mm']:g} mm, from the recorded sweep "
            f"`{record['source']}`: " + "; ".join(parts) + ".")


ANSWER_WORDS = {"max_deflection_mm": "max deflection", "drill_point_deflection_mm": "drill-point deflection",
                "f1_Hz": "f1", "governing_margin": "governing margin"}


def _answer(key: str) -> str:
    if key in ANSWER_WORDS:
        return ANSWER_WORDS[key]
    if key.startswith("von_mises_beyond_"):
        return "σ_vM beyond " + key[len("von_mises_beyond_"):-len("mm_MPa")] + " mm"
    return "σ_vM at " + key[len("von_mises_"):-len("mm_MPa")] + " mm"


def sensitivity_section(sens: dict) -> list[str]:
    """The one-at-a-time table: each modelling choice's change of every answer [%], beside the
    verification's uncertainty of the same answer."""
    keys = list(sens["baseline"])
    lines = ["**Sensitivity to modelling choices** (docs/study.md): each choice changed alone; the change of "
             "every answer in per cent of the baseline (near-hole answers at the deepest station, "
             f"{sens['station']}; deflections quasi-static; \"=\": the choice cannot change that answer). The last "
             f"row is this run's own discretisation uncertainty of the same answers (its verification). "
             f"{cost_sentence(sens, 'Cost')}", "",
             "| choice | setting (baseline) | " + " | ".join(_answer(k) for k in keys) + " |",
             "|---|---|" + "---|" * len(keys)]
    lines.append("| baseline | | " + " | ".join(_fmt(sens["baseline"][k], 4) for k in keys) + " |")
    for row in sens["rows"]:
        cells = [("=" if row["changes_percent"].get(k) is None and not row.get("not_computed") else
                  f"{row['changes_percent'][k]:+.1f} %" if row["changes_percent"].get(k) is not None
                  and math.isfinite(row["changes_percent"][k]) else "–") for k in keys]
        note = f" (not computed: {row['not_computed']})" if row.get("not_computed") else ""
        lines.append(f"| {row['choice']} | {row['setting']} ({row['baseline']}){note} | " + " | ".join(cells) + " |")
    mesh = sens.get("mesh_uncertainty_percent") or {}
    lines.append("| discretisation (verification) | | " + " | ".join(
        f"±{mesh[k]:.1f} %" if mesh.get(k) is not None and math.isfinite(mesh[k]) else "–" for k in keys) + " |")
    return lines


def dynamics_paragraph(dyn: dict, step_s: float) -> str:
    """Why the response is (or is not) quasi-static, with the resolved run's amplification."""
    f1 = dyn["frequencies_Hz"][0]
    text = (f"Lowest natural frequency {f1:.1f} Hz (period {1e3 / f1:.2f} ms). The drilling loads change over "
            f"seconds (the clogging growth) and oscillate at the flute-passing frequency "
            f"({dyn['flute_passing_Hz']:.0f} Hz) when the flute-passing content is modelled, both far below "
            f"{f1:.0f} Hz, so inertia adds little and the response follows the loads quasi-statically; the "
            f"{step_s:g} s steps of the main transient sample that quasi-static response."
            if dyn.get("flute_passing_Hz") else
            f"Lowest natural frequency {f1:.1f} Hz (period {1e3 / f1:.2f} ms) against {step_s:g} s steps.")
    if dyn.get("resolved_steps"):
        window = dyn.get("resolved_window_s") or (0.0, 0.0)
        text += (f" A resolved transient from {window[0]:.2f} to {window[1]:.2f} s "
                 f"({dyn['resolved_steps']:,} steps of {1e3 * dyn['resolved_step_s']:.3g} ms, "
                 f"{dyn['resolved_vectors']} Ritz vectors, error indicator {dyn['resolved_indicator']:.1e}) with the "
                 f"per-flute oscillation and the breakthrough release gives a peak deflection of "
                 f"{dyn['resolved_peak_mm']:.5g} mm against {dyn['quasi_static_peak_mm']:.5g} mm quasi-static: "
                 f"dynamic amplification {dyn['dynamic_amplification']:.4f} (drill point "
                 f"{dyn['resolved_drill_point_mm'] / dyn['quasi_static_drill_point_mm']:.4f}).")
    return text


def study_table(summaries: list[dict]) -> str:
    """All sites beside the thesis's Tables 5-14 and 5-15, as Markdown: the bone set whose
    friction drove the clogging load, and which thesis row (if any) a row compares with."""
    lines = ["| site | friction | thesis row | max deflection dynamic [mm] | static [mm] | ratio | thesis dyn. | "
             "thesis stat. | max von Mises dynamic [MPa] | static [MPa] | ratio | thesis dyn. | thesis stat. | "
             "von Mises outside exclusion, dynamic [MPa] | von Mises at δ from the hole wall, dynamic [MPa] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summaries:
        res = s["results"]
        d, v, ve = res["max_deflection_mm"], res["max_von_mises_MPa"], res["max_von_mises_excl_MPa"]
        row = THESIS_SITE.get(s["site"]["name"].lower())
        td, tv = thesis_values(s["site"]["name"]) or ((None, None), (None, None))
        marked = " (OUT OF RANGE, --force)" if s.get("out_of_range") else ""
        lines.append(f"| {s['site']['name']}{marked} | {s['loading']['bone_set']} | {row or 'none (not a thesis site)'} | "
                     f"{_fmt(d['dynamic']['value'])} | {_fmt(d['static']['value'])} | "
                     f"{_fmt(d['ratio_dynamic_to_static'], 3)} | {_fmt(td[0])} | {_fmt(td[1])} | "
                     f"{_fmt(v['dynamic']['value'])} | {_fmt(v['static']['value'])} | "
                     f"{_fmt(v['ratio_dynamic_to_static'], 3)} | {_fmt(tv[0])} | {_fmt(tv[1])} | "
                     f"{_fmt(ve['dynamic']['value'])} | {hole_headline_cell(s)} |")
    return "\n".join(lines)


def study_discussion(summaries: list[dict]) -> str:
    """Why the numbers differ from the thesis's Tables 5-14/5-15, with this study's load ratios."""
    def ratio(a, b):
        return f"{a / b:.2f}x" if b > 0 else "undefined (no static load)"

    def load_sentence(load):
        return (f"the chip-clogging thrust at breakthrough is {ratio(load['peak_thrust_N'], load['static_thrust_N'])} "
                f"the static Allotta thrust ({load['peak_thrust_N']:.1f} N against {load['static_thrust_N']:.1f} N) "
                f"and the torque {ratio(load['peak_torque_Nmm'], load['static_torque_Nmm'])} "
                f"({load['peak_torque_Nmm']:.1f} against {load['static_torque_Nmm']:.1f} N·mm)")

    keys = ("peak_thrust_N", "static_thrust_N", "peak_torque_Nmm", "static_torque_Nmm")
    loads = [s["loading"] for s in summaries]
    if all(all(abs(l[k] - loads[0][k]) <= 1e-9 * max(1.0, abs(loads[0][k])) for k in keys) for l in loads):
        load_text = f"Here {load_sentence(loads[0])}."
    else:
        load_text = "The loads differ between cases: " + "; ".join(
            f"{s['case']['name']}: {load_sentence(s['loading'])}" for s in summaries) + "."
    periods = [1 / s["dynamics"]["frequencies_Hz"][0] for s in summaries if s.get("dynamics", {}).get("frequencies_Hz")]
    period = f"at most {1e3 * max(periods):.1f} ms" if periods else "a few ms on a femur"
    step = summaries[0]["case"]["time"]["step_s"]
    return f"""\
Why the numbers differ from the thesis's Tables 5-14/5-15:

- **Loads.** The response is quasi-static (lowest natural period {period} against {step:g} s steps; see
  each report's modal paragraph), so every dynamic/static ratio is a ratio of loads. {load_text}
  Deflection follows the thrust; the peak stress under the drill follows the torque's shear, so the
  two ratios differ. The thesis reports one ratio, 4.76, for both deflection and
  stress at every site, as if both loads had been scaled by one factor; its own calibrated clogging model
  does not grow that much over a 6 mm cortex at 2 mm/s and 1500 rpm, and its static Allotta load used
  specific cutting energies it does not state (docs/study.md).
- **Geometry.** The thesis used a commercial solid femur meshed by ANSYS at 22 mm; femstudy uses its
  built-in femur (or your surface) with the canal carved inside a cortex of the case's thickness profile.
  Local cortical thickness and the section's second moment of area set deflection and stress.
- **Load patch versus point load.** The thesis applied force and torque at a point. A point load on a 3-D
  continuum has unbounded local displacement and stress, so its "maximum" depends on the mesh. femstudy
  spreads the thrust over the drill footprint (Ø 2.7 mm) and the torque as a shear growing with radius.
  The peak stress under the patch is finite but mesh-sensitive (its convergence is assessed by
  `femstudy sweep`); the stress outside the exclusion radius is bounded and the measure to quote,
  with its mesh sensitivity (a few per cent between the finest meshes, docs/convergence.md). The thesis's
  proximal and distal stresses (0.31 and 0.19 MPa against 21.8 MPa at mid-diaphysis, under the same loads)
  cannot be peaks under the drill point and were presumably read elsewhere.
- **Element order and size.** 22 mm elements cannot resolve a drill-sized load. femstudy uses P2
  tetrahedra refined to about 1 mm at the site.
- **Clamp extent and site position.** Both ends are fixed over the case's clamp length of surface; the
  thesis fixes end faces of unstated extent. The proximal and distal sites sit between the metaphysis and
  the clamp, where the clamp extent and the exact position change the deflection most.
"""
