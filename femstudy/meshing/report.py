"""Files describing a meshed femur: VTU mesh, quality report, frame, landmarks, picture."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from femstudy.femur_mesh import CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL, REGION_NAMES

REGION_COLOURS = {CORTICAL: "#cdb67c", CANCELLOUS_PROXIMAL: "#e07b39", CANCELLOUS_DISTAL: "#6a8fc7"}


def to_grid(model):
    """The mesh as a ``pyvista.UnstructuredGrid`` with region and clamp arrays."""
    import pyvista as pv

    m = model.mesh
    grid = pv.UnstructuredGrid({pv.CellType.TETRA: m.tets}, m.points)
    grid.cell_data["region"] = m.region
    grid.point_data["clamp_proximal"] = model.clamps.proximal.astype(np.uint8)
    grid.point_data["clamp_distal"] = model.clamps.distal.astype(np.uint8)
    return grid


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def landmarks_dict(model) -> dict:
    s = model.site
    return {"site": {"name": s.name, "entry_point_mm": s.entry_point, "outward_normal": s.outward_normal,
                     "drill_direction": s.direction, "cortical_thickness_mm": s.cortical_thickness_mm,
                     "facets_in_drill_disk": model.stats["site_facets_in_drill_disk"],
                     "median_facet_edge_at_site_mm": model.stats["site_edge_mm"]},
            "clamps": {"proximal_nodes": int(model.clamps.proximal.sum()),
                       "distal_nodes": int(model.clamps.distal.sum())}}


def summary_text(model) -> str:
    """A readable account of the frame, the mesh, its regions, quality and landmarks."""
    f, st, q, s = model.frame, model.stats, model.quality, model.site
    lines = [
        f"surface   {st['surface_file']}",
        f"frame     {f.side} femur, {f.length_mm:.1f} mm long, units {f.units} (x{f.scale_to_mm:g} to mm)"
        + (f"; set by the case file: {', '.join(f.overridden)}" if f.overridden else "; all detected"),
        f"          proximal {np.round(f.up, 3).tolist()}, anterior {np.round(f.anterior, 3).tolist()}, "
        f"medial {np.round(f.medial, 3).tolist()}",
        f"mesh      {st['n_tets']} tets, {st['n_points']} nodes, target edge {st['size_mm']:g} mm, "
        f"envelope {st['envelope']:g} of the box diagonal",
        f"TetWild   {st['tetwild_seconds']:.1f} s on {st['input_triangles']['tetwild']} input triangles"
        + (" (this run loaded it from the cache)" if st["cache_hit"] else ""),
        f"volume    tets {st['tet_volume_mm3']:.0f} mm^3 = surface {st['surface_volume_mm3']:.0f} - canal "
        f"{st['canal_volume_mm3']:.0f} {100 * (st['tet_volume_mm3'] / (st['surface_volume_mm3'] - st['canal_volume_mm3']) - 1):+.2f} %",
        f"canal     equivalent diameter at mid-length {st['canal_midshaft_diameter_mm']:.1f} mm",
        "regions   " + "; ".join(f"{name} {v['tets']} tets, {v['volume_mm3']:.0f} mm^3"
                                 for name, v in st["regions"].items()),
        f"quality   min dihedral {q['min_dihedral_deg']:.1f} deg (1st percentile of per-tet minimum "
        f"{q['dihedral_deg_p1']:.1f}), max {q['max_dihedral_deg']:.1f} deg",
        f"          radius ratio 3 r_in/R_circ: min {q['radius_ratio_min']:.3f}, percentiles "
        + ", ".join(f"p{k} {v:.3f}" for k, v in q["radius_ratio_percentiles"].items())
        + f"; {q['n_poor']} tets below {q['poor_radius_ratio_below']:g}",
        f"          edges {q['edge_mm']['min']:.2f} / {q['edge_mm']['median']:.2f} / {q['edge_mm']['max']:.2f} mm "
        "(min / median / max)",
        f"site      {s.name}: entry {np.round(s.entry_point, 2).tolist()} mm, drill direction "
        f"{np.round(s.direction, 3).tolist()}, cortex {s.cortical_thickness_mm:.2f} mm along the drill axis",
        f"          {st['site_facets_in_drill_disk']} boundary facets in the r = {st['drill_radius_mm']:g} mm load disk, "
        f"median edge there {st['site_edge_mm']:.2f} mm",
        f"clamps    {int(model.clamps.proximal.sum())} proximal and {int(model.clamps.distal.sum())} distal "
        "surface nodes",
    ]
    if st.get("repairs"):
        lines.append("input     " + "; ".join(st["repairs"]))
    return "\n".join(lines)


def write_outputs(model, folder: Path, screenshot: bool = True) -> list[str]:
    """Write mesh.vtu, quality.json/.txt, frame.json, landmarks.json and mesh.png into ``folder``
    (callers make the folder appear atomically, see :func:`femstudy.atomic.atomic_folder`)."""
    to_grid(model).save(folder / "mesh.vtu")
    (folder / "quality.json").write_text(json.dumps(_jsonable({"quality": model.quality, "stats": model.stats}),
                                                    indent=1), encoding="utf-8")
    (folder / "quality.txt").write_text(summary_text(model) + "\n", encoding="utf-8")
    (folder / "frame.json").write_text(json.dumps(_jsonable(model.frame.as_dict()), indent=1), encoding="utf-8")
    (folder / "landmarks.json").write_text(json.dumps(_jsonable(landmarks_dict(model)), indent=1), encoding="utf-8")
    names = ["mesh.vtu", "quality.json", "quality.txt", "frame.json", "landmarks.json"]
    if screenshot:
        cut_picture(model, folder / "mesh.png")
        names.append("mesh.png")
    return names


def _canal_wall(model):
    """The canal's wall: boundary faces that are not on the outer surface."""
    import pyvista as pv

    from femstudy.meshing import landmarks

    every = landmarks.boundary_faces(model.mesh)
    outer = landmarks.outer_faces(model.mesh, model.frame)
    outer_keys = {tuple(sorted(f)) for f in outer.tolist()}
    wall = np.array([f for f in every.tolist() if tuple(sorted(f)) not in outer_keys]).reshape(-1, 3)
    return pv.PolyData.from_regular_faces(model.mesh.points, wall)


def _half(grid, wall, normal, origin, crinkle=False):
    """The half of the mesh behind a plane, as a surface coloured by region, the canal's wall
    (where the canal is cut open) shown with code 0."""
    half = grid.clip(normal=normal, origin=origin, crinkle=crinkle).extract_surface(algorithm=None)
    if wall.n_cells and half.n_cells:
        d = half.cell_centers().compute_implicit_distance(wall)["implicit_distance"]
        half.cell_data["region"] = np.where(np.abs(d) < 1e-6, 0, half.cell_data["region"])
    return half


def cut_picture(model, path: Path) -> None:
    """Four views: the femur cut in half through the canal's centreline, seen from anterior
    (coronal cut) and from lateral (sagittal cut); the elements around the drill site in
    section; and the outer surface's facets under the drill-load disk, seen along the drill."""
    import pyvista as pv

    from femstudy.meshing import landmarks

    pv.OFF_SCREEN = True
    f, s = model.frame, model.site
    grid = to_grid(model)
    wall = _canal_wall(model)
    centre = model.canal_axis[len(model.canal_axis) // 2]
    entry = s.entry_point
    colours = {0: "#5a1a1a", **REGION_COLOURS}
    codes = sorted(colours)
    style = dict(scalars="region", cmap=[colours[c] for c in codes], clim=[codes[0] - 0.5, codes[-1] + 0.5],
                 n_colors=len(codes), show_scalar_bar=False)
    plotter = pv.Plotter(shape=(1, 5), col_weights=[1, 1, 1, 1, 0.75], window_size=(2200, 1250),
                         off_screen=True, border=False)

    def camera(origin, view, scale):
        plotter.camera.focal_point = origin
        plotter.camera.position = origin + np.asarray(view) * 4 * f.length_mm
        plotter.camera.up = tuple(f.up)
        plotter.camera.parallel_projection = True
        plotter.camera.parallel_scale = scale

    for i, (title, view) in enumerate([("coronal cut, from anterior", f.anterior),
                                       ("sagittal cut, from lateral", -f.medial)]):
        plotter.subplot(0, i)
        plotter.add_mesh(_half(grid, wall, view, centre), **style)
        plotter.add_mesh(pv.Arrow(start=entry - s.direction * 25, direction=s.direction, scale=25), color="black")
        plotter.add_text(title, font_size=10, color="black")
        plotter.add_text(f"view height {1.1 * f.length_mm:.0f} mm", position="lower_left", font_size=8, color="black")
        camera(centre, view, 0.55 * f.length_mm)
    plotter.subplot(0, 4)
    entries = [(REGION_NAMES[c].replace("_", " "), colours[c]) for c in codes if c]
    entries += [("canal wall (the canal is empty)", colours[0]), ("drill axis", "black"),
                (f"load disk, r = {model.stats['drill_radius_mm']:g} mm", "#1f4fd0")]
    for k, (label, colour) in enumerate(entries):
        plotter.add_text(label, position=(0.04, 0.62 - 0.045 * k), viewport=True, font_size=11, color=colour)
    plotter.subplot(0, 2)
    side = np.cross(f.up, s.direction)
    plotter.add_mesh(_half(grid, wall, side, entry), show_edges=True, edge_color="#444444", line_width=0.6, **style)
    plotter.add_mesh(pv.Arrow(start=entry - s.direction * 6, direction=s.direction, scale=5.5), color="black")
    plotter.add_text(f"drill site in section\ncortex {s.cortical_thickness_mm:.1f} mm along the drill",
                     font_size=10, color="black")
    plotter.add_text("view height 30 mm", position="lower_left", font_size=8, color="black")
    plotter.camera.focal_point = entry + 4 * s.direction
    plotter.camera.position = entry + 4 * s.direction + side * 200
    plotter.camera.up = tuple(-s.direction)
    plotter.camera.parallel_projection = True
    plotter.camera.parallel_scale = 15.0
    plotter.subplot(0, 3)
    outer = pv.PolyData.from_regular_faces(model.mesh.points, landmarks.outer_faces(model.mesh, f))
    plotter.add_mesh(outer.clip_box(np.repeat(entry, 2) + np.tile([-8.0, 8.0], 3), invert=False),
                     color=REGION_COLOURS[CORTICAL], show_edges=True, edge_color="#444444", line_width=0.8)
    radius = model.stats["drill_radius_mm"]
    ring = pv.Circle(radius=radius, resolution=60)
    normal = s.outward_normal
    ring.points = _in_plane(ring.points, entry + 0.05 * normal, normal)
    plotter.add_mesh(ring.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False),
                     color="#1f4fd0", line_width=4)
    plotter.add_text(f"outer surface at the drill site\n{model.stats['site_facets_in_drill_disk']} facets in "
                     f"the r = {radius:g} mm load disk", font_size=10, color="black")
    plotter.add_text("view height 12 mm", position="lower_left", font_size=8, color="black")
    plotter.camera.focal_point = entry
    plotter.camera.position = entry + normal * 200
    plotter.camera.up = tuple(f.up)
    plotter.camera.parallel_projection = True
    plotter.camera.parallel_scale = 6.0
    plotter.set_background("white")
    plotter.screenshot(str(path))
    plotter.close()


def _in_plane(xy: np.ndarray, origin: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Map points of the z = 0 plane into the plane through ``origin`` normal to ``normal``."""
    n = normal / np.linalg.norm(normal)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return origin + np.outer(xy[:, 0], u) + np.outer(xy[:, 1], v)
