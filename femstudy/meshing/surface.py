"""Reading, checking and preparing a closed bone surface.

A user's STL/OBJ/PLY/VTP/VTK file is read with PyVista (meshio as a fallback for formats
VTK does not know), triangulated and cleaned (coincident points merged). It must then be a
closed, edge-manifold, single-shell surface: holes and extra shells are refused with one
clear sentence, since guessing how to close a bone would silently change its stiffness.
What *is* repaired (duplicate points, non-triangle faces, degenerate or duplicate triangles,
inconsistent or inward orientation) is listed in :attr:`Surface.repairs`.
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from femstudy.errors import UserError, require
from femstudy.meshing.intersections import self_intersections

SUFFIXES = (".stl", ".obj", ".ply", ".vtp", ".vtk", ".vtu", ".off")
#: Largest surface read: femstudy simplifies every surface to a few thousand triangles before
#: TetWild (femstudy.meshing.model.surface_edge_mm), and a CT femur needs no more than a few
#: hundred thousand; a file announcing more is refused before anything is allocated.
MAX_TRIANGLES = 2_000_000
MAX_POINTS = 2_000_000
#: Largest surface file [bytes]: an ASCII STL of MAX_TRIANGLES is about 500 MB.
MAX_SURFACE_BYTES = 600 * 2 ** 20
#: Fewest bytes one point or face takes in a file (three ASCII digits and separators; a
#: binary float triple is 12), to check a header's counts against the file's size.
MIN_BYTES_PER_ITEM = 6


@dataclass
class Surface:
    """A closed triangulated surface: points (n, 3) and outward-oriented triangles (m, 3)."""

    points: np.ndarray
    triangles: np.ndarray
    source: str
    repairs: list[str] = field(default_factory=list)

    def polydata(self):
        """The surface as a ``pyvista.PolyData``."""
        import pyvista as pv

        return pv.PolyData.from_regular_faces(self.points, self.triangles)

    @property
    def volume(self) -> float:
        """Enclosed volume by the divergence theorem, V = Σ x0 · (x1 × x2) / 6 [units³]."""
        v = self.points[self.triangles]
        return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)

    @property
    def area(self) -> float:
        v = self.points[self.triangles]
        return float(0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum())

    def scaled(self, factor: float) -> "Surface":
        return Surface(self.points * factor, self.triangles, self.source, list(self.repairs))


def surface_samples(points: np.ndarray, triangles: np.ndarray, per_extent: int = 80):
    """Centres, unit outward normals and areas of a closed surface's triangles.

    Triangles longer than 1/``per_extent`` of the bone are first subdivided, so that every
    slice along the bone holds samples even on a coarse triangulation (a CAD export with long
    slivers, say). Normals point outwards whichever way the triangles are wound: they are
    flipped if the enclosed volume Σ x0 · (x1 × x2) / 6 comes out negative.

    Parameters
    ----------
    points, triangles
        The surface: (n, 3) coordinates and (m, 3) vertex indices.

    Returns
    -------
    centres (k, 3), normals (k, 3), areas (k,)

    Examples
    --------
    >>> import pyvista as pv
    >>> box = pv.Box().triangulate()
    >>> x, n, a = surface_samples(np.asarray(box.points), box.regular_faces)
    >>> round(float(a.sum()), 6), bool((np.einsum("ij,ij->i", x, n) > 0).all())
    (24.0, True)
    """
    import pyvista as pv

    extent = float(np.ptp(points, axis=0).max())
    v = points[triangles]
    outward = np.sign(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum()) or 1.0
    if np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2).max() > extent / per_extent:
        fine = pv.PolyData.from_regular_faces(points, triangles).subdivide_adaptive(max_edge_len=extent / per_extent)
        v = np.asarray(fine.points, float)[fine.regular_faces]
    cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    twice_area = np.linalg.norm(cross, axis=1)
    normals = outward * cross / np.maximum(twice_area, np.finfo(float).tiny)[:, None]
    return v.mean(axis=1), normals, 0.5 * twice_area


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes, read once per file version in a process (a study asks for its
    surface's digest for the estimate, the kept size and the mesh cache's key)."""
    stat = Path(path).stat()
    return _file_digest(str(Path(path).resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=16)
def _file_digest(path: str, mtime_ns: int, size: int) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def check_surface_file(path: Path) -> None:
    """Raise :class:`UserError` unless ``path`` is a readable, non-empty file of a known format.

    Examples
    --------
    >>> check_surface_file(Path("/"))
    Traceback (most recent call last):
    femstudy.errors.UserError: / is a folder, not a surface file
    """
    if path.is_dir():
        inside = sorted(p.name for p in path.iterdir() if p.suffix.lower() in SUFFIXES)
        hint = f" (it holds {', '.join(inside[:3])}{', ...' if len(inside) > 3 else ''}: name one of them)" if inside else ""
        raise UserError(f"{path} is a folder, not a surface file{hint}")
    require(path.exists(), f"surface file {path} does not exist")
    require(path.is_file(), f"surface file {path} is not a regular file")
    try:
        with open(path, "rb") as fh:
            fh.read(1)
    except OSError as exc:
        raise UserError(f"cannot read surface file {path}: {exc.strerror or exc}") from None
    require(path.stat().st_size > 0, f"surface file {path} is empty")
    require(path.suffix.lower() in SUFFIXES,
            f"surface file {path} has an unknown format '{path.suffix}' (use one of {', '.join(SUFFIXES)})")
    size = path.stat().st_size
    require(size <= MAX_SURFACE_BYTES, f"surface file {path} is {size / 2 ** 20:.0f} MB; femstudy reads surfaces up "
                                       f"to {MAX_SURFACE_BYTES // 2 ** 20} MB ({MAX_TRIANGLES:,} triangles): decimate "
                                       "it first (it is simplified to a few thousand triangles anyway)")


def _is_text(data: bytes) -> bool:
    """Whether ``data`` is plain ASCII text (tabs and line ends allowed)."""
    return all(32 <= b < 127 or b in (9, 10, 13) for b in data)


def _check_stl_complete(path: Path) -> None:
    """Refuse an STL file that stops early or announces more than it holds (VTK would read the
    part that is there and report holes, or allocate what the header claims and abort). A
    binary STL is an 80-byte header, a 4-byte triangle count n and n records of 50 bytes; an
    ASCII one is text that starts with "solid" and ends with "endsolid"."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(512)
        fh.seek(max(size - 512, 0))
        tail = fh.read()
    announced = int.from_bytes(head[80:84], "little") if len(head) >= 84 else -1
    if 84 + 50 * announced == size:
        require(announced <= MAX_TRIANGLES, f"surface file {path} holds {announced:,} triangles; femstudy reads up to "
                                            f"{MAX_TRIANGLES:,}: decimate it first (it is simplified to a few thousand "
                                            "triangles anyway)")
        return
    if head[:5].lower() == b"solid" and _is_text(head):
        if b"endsolid" not in tail.lower():
            raise UserError(f"cannot read surface file {path}: the ASCII STL is cut short (it does not end with 'endsolid')")
        return
    if len(head) < 84:
        raise UserError(f"cannot read surface file {path}: at {size} bytes it is too short to be an STL file")
    if 84 + 50 * announced > size:
        held = max(size - 84, 0) // 50
        raise UserError(f"cannot read surface file {path}: it is cut short or not an STL file (it holds {held:,} "
                        f"of the {announced:,} triangles its binary STL header announces)")


_COUNT_PATTERNS = {  # header lines that announce how many points and faces follow
    ".ply": rb"element\s+(?:vertex|face)\s+(\d+)",
    ".vtk": rb"(?:POINTS|POLYGONS|CELLS|TRIANGLE_STRIPS)\s+(\d+)",
    ".vtu": rb"Number\s*Of\s*(?:Points|Cells|Polys)\s*=\s*\"(\d+)\"",
    ".vtp": rb"Number\s*Of\s*(?:Points|Cells|Polys)\s*=\s*\"(\d+)\"",
}


def _check_header_counts(path: Path) -> None:
    """Refuse a file whose header announces more points or faces than femstudy reads, or
    than its size can hold, before a reader allocates them (an STL by its own rule,
    :func:`_check_stl_complete`; an OFF by its counts line)."""
    import re

    suffix, size = path.suffix.lower(), path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(64 * 1024)
    if suffix == ".stl":
        return _check_stl_complete(path)
    if suffix == ".off":
        lines = [ln.split(b"#")[0].strip() for ln in head.splitlines()]
        lines = [ln for ln in lines if ln]
        if lines and lines[0].upper().endswith(b"OFF"):
            counts = (lines[0][:-3].split() or (lines[1].split() if len(lines) > 1 else []))[:2]
            claims = [int(c) for c in counts if c.isdigit()]
        else:
            claims = []
    elif suffix in _COUNT_PATTERNS:
        claims = [int(c) for c in re.findall(_COUNT_PATTERNS[suffix], head, flags=re.IGNORECASE)]
    else:
        return
    for claim in claims:
        require(claim <= max(MAX_POINTS, MAX_TRIANGLES),
                f"surface file {path}: its header announces {claim:,} points or faces; femstudy reads up to "
                f"{MAX_TRIANGLES:,}: decimate it first")
        compressed = suffix in (".vtu", ".vtp")  # XML files may hold compressed data
        require(compressed or claim * MIN_BYTES_PER_ITEM <= size,
                f"cannot read surface file {path}: its header announces {claim:,} points or faces, more than "
                f"its {size:,} bytes can hold (is it a complete {suffix.lstrip('.').upper()} file?)")


def _read_any(path: Path):
    """Read ``path`` into a PolyData of its outer faces, or raise UserError.

    VTK reads it, and meshio when VTK fails or finds nothing; the first complaint is the
    one reported. PLY goes to meshio alone: VTK's PLY reader crashes the process on a
    truncated binary file.
    """
    import logging
    import warnings

    import pyvista as pv

    _check_header_counts(path)
    mesh, complaint = None, ""
    if path.suffix.lower() != ".ply":
        try:
            with pv.vtk_verbosity("off"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                logging.disable(logging.CRITICAL)  # VTK reader errors are reported below, in one line
                try:
                    mesh = pv.read(path)
                finally:
                    logging.disable(logging.NOTSET)
        except Exception as exc:  # VTK readers raise many types
            complaint = _first_line(exc)
    if (mesh is None or mesh.n_cells == 0) and path.suffix.lower() in MESHIO_READERS:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                mesh = _read_meshio(path)
        except UserError:
            raise
        except Exception as exc:  # meshio's readers raise many types too
            complaint = complaint or _first_line(exc)
    if mesh is None:
        raise UserError(f"cannot read surface file {path}: {complaint} "
                        f"(is it a complete {path.suffix.lstrip('.').upper()} file?)")
    if isinstance(mesh, pv.MultiBlock):
        mesh = mesh.combine()
    if not isinstance(mesh, pv.PolyData):
        mesh = mesh.extract_surface(algorithm=None)
    if mesh.n_cells == 0 and complaint:
        raise UserError(f"cannot read surface file {path}: {complaint}")
    return mesh


#: meshio's reader of each format it shares with VTK (called directly: ``meshio.read`` exits
#: the process when a reader fails)
MESHIO_READERS = {".stl": "stl", ".obj": "obj", ".ply": "ply", ".vtk": "vtk", ".vtu": "vtu", ".off": "off"}


def _first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__


def _read_meshio(path: Path):
    """``path`` read by meshio, as a PolyData of its triangles and polygons."""
    import meshio
    import pyvista as pv

    m = getattr(meshio, MESHIO_READERS[path.suffix.lower()]).read(str(path))
    cells = [c for c in m.cells if c.type in ("triangle", "quad", "polygon")]
    if not cells:
        raise UserError(f"surface file {path} holds no triangles or polygons")
    faces = np.hstack([np.column_stack([np.full(len(c.data), c.data.shape[1]), c.data]).ravel() for c in cells])
    return pv.PolyData(np.asarray(m.points, float)[:, :3], faces)


def read_points(path: str | Path):
    """Read a surface file into a PolyData after checking what can be checked first: the
    file (:func:`check_surface_file`), its header's counts against its size and
    :data:`MAX_TRIANGLES`, and then the points: finite, and spanning what a femur spans in
    mm, cm, m or inches (a file scaled by 1e30 is refused here, not handed to VTK's filters).
    """
    from femstudy.meshing.units import UNIT_RANGES

    path = Path(path)
    check_surface_file(path)
    mesh = _read_any(path)
    require(mesh.n_cells <= MAX_TRIANGLES and mesh.n_points <= MAX_POINTS,
            f"surface file {path} holds {mesh.n_cells:,} faces and {mesh.n_points:,} points; femstudy reads up to "
            f"{MAX_TRIANGLES:,}: decimate it first")
    points = np.asarray(mesh.points, float)
    require(np.isfinite(points).all(), f"surface file {path} has non-finite point coordinates")
    if len(points):
        extent = float(np.ptp(points, axis=0).max())
        lo, hi = min(r[0] for r in UNIT_RANGES.values()), max(r[1] for r in UNIT_RANGES.values())
        require(lo / 10 <= extent <= hi * 10,
                f"surface file {path} spans {extent:.3g} in its own units: no femur is that long in mm, cm, m or "
                "inches (expected 200-750 mm, 24.5-75 cm, 0.2-0.75 m or 8-24 in); is it scaled?")
    return mesh


def read_surface(path: str | Path, bodies: str = "one") -> Surface:
    """Read, clean and check a closed surface file; raise :class:`UserError` if unusable.

    Parameters
    ----------
    path
        STL, OBJ, PLY, VTP, VTK, VTU or OFF file.
    bodies
        ``"one"`` refuses a file holding several separate bodies (naming their sizes);
        ``"largest"`` keeps the one with the largest area and says so in ``repairs``.

    Returns
    -------
    Surface

    Examples
    --------
    >>> from femstudy.meshing.builtin_femur import BUILTIN_STL
    >>> len(read_surface(BUILTIN_STL).triangles)
    12000
    """
    path = Path(path)
    mesh = read_points(path)
    require(mesh.n_points > 0 and mesh.n_cells > 0,
            f"cannot read surface file {path}: no triangles in it (is it a valid {path.suffix.lstrip('.').upper()} file?)")
    extent = np.ptp(np.asarray(mesh.points, float), axis=0)
    require(extent.min() > 1e-6 * extent.max(),
            f"surface file {path} is a flat (2-D) mesh; give the closed outer surface of the bone")
    return prepare(mesh, str(path), bodies)


def prepare(mesh, source: str, bodies: str = "one") -> Surface:
    """Triangulate, clean, keep one body, check closed/manifold and orient outwards.

    ``bodies``: ``"one"`` refuses several separate bodies, ``"largest"`` keeps the largest.
    """
    repairs: list[str] = []
    if not mesh.is_all_triangles:
        mesh = mesh.triangulate()
        repairs.append("split polygons into triangles")
    n_points = mesh.n_points
    mesh = mesh.clean(tolerance=1e-9, absolute=False)
    if mesh.n_points < n_points:
        repairs.append(f"merged {n_points - mesh.n_points} duplicate points")
    tri = mesh.regular_faces if mesh.n_cells else np.empty((0, 3), int)
    pts = np.asarray(mesh.points, dtype=np.float64)
    tri, dropped = _drop_degenerate_and_duplicate(pts, tri)
    if dropped:
        repairs.append(f"removed {dropped} degenerate or duplicate triangles")
    require(len(tri) >= 4, f"{source}: fewer than 4 valid triangles; not a closed surface")
    tri, note = _one_body(pts, tri, source, bodies)
    if note:
        repairs.append(note)
    _check_closed_manifold(tri, source)
    used = np.unique(tri)
    if len(used) < len(pts):
        remap = np.full(len(pts), -1)
        remap[used] = np.arange(len(used))
        pts, tri = pts[used], remap[tri]
    tri, flipped = _orient_consistently(tri)
    if flipped:
        repairs.append(f"made the orientation of {flipped} triangles consistent")
    crossing = self_intersections(pts, tri)
    if len(crossing):
        where = ", ".join(f"{x:.4g}" for x in pts[tri[crossing[0, 0]]].mean(axis=0))
        raise UserError(f"{source}: the surface intersects itself ({len(crossing)} pairs of triangles cross, "
                        f"the first near ({where}) in the file's units); repair it in a mesh editor first")
    surf = Surface(pts, tri, source, repairs)
    if surf.volume < 0:
        surf.triangles = surf.triangles[:, ::-1].copy()
        repairs.append("turned inward-facing triangles outwards")
    return surf


def _one_body(pts, tri, source, bodies) -> tuple[np.ndarray, str]:
    """The triangles of the only body, or of the largest (by area) with ``bodies = "largest"``,
    and a note of what was dropped. Bodies are sets of triangles connected through shared
    vertices; a femur exported with its patella, or with loose fragments, has several."""
    labels = _body_labels(tri, len(pts))
    count = int(labels.max()) + 1
    if count == 1:
        return tri, ""
    v = pts[tri]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    order = np.argsort(np.bincount(labels, weights=area))[::-1]
    sizes = [(int((labels == b).sum()), float(np.ptp(pts[np.unique(tri[labels == b])], axis=0).max())) for b in order]
    listed = ", ".join(f"{n:,} triangles spanning {extent:.3g}" for n, extent in sizes[:3])
    more = f" and {count - 3} smaller" if count > 3 else ""
    if bodies != "largest":
        raise UserError(f"{source}: the surface has {count} separate shells (bodies: {listed}{more}, in the file's units); "
                        "set geometry.bodies = \"largest\" to mesh the largest alone, or remove the others (loose "
                        "fragments, a patella, inner surfaces) in a mesh editor")
    return tri[labels == order[0]], f"kept the largest of {count} bodies ({listed}{more})"


def _drop_degenerate_and_duplicate(pts, tri):
    v = pts[tri]
    area2 = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    scale = np.ptp(pts, axis=0).max() if len(pts) else 1.0
    ok = (area2 > 1e-14 * scale ** 2) & (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
    tri = tri[ok]
    _, first = np.unique(np.sort(tri, axis=1), axis=0, return_index=True)
    keep = np.sort(first)
    return tri[keep], int((~ok).sum() + (len(tri) - len(keep)))


def _edges(tri):
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    return np.sort(e, axis=1)


def _check_closed_manifold(tri, source):
    _, counts = np.unique(_edges(tri), axis=0, return_counts=True)
    open_edges, over = int((counts == 1).sum()), int((counts > 2).sum())
    require(open_edges == 0, f"{source}: the surface is not closed ({open_edges} boundary edges); "
                             "close its holes in a mesh editor first")
    require(over == 0, f"{source}: the surface is not manifold ({over} edges shared by more than two "
                       "triangles); repair it in a mesh editor first")


def _body_labels(tri, n_points) -> np.ndarray:
    """Body number (0, 1, ...) of every triangle: its connected component through shared vertices."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = _edges(tri)
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_points, n_points))
    _, labels = connected_components(graph, directed=False)
    _, body = np.unique(labels[tri[:, 0]], return_inverse=True)
    return body.ravel()


def _orient_consistently(tri):
    """Flip triangles so that every shared edge is traversed in opposite directions.

    Breadth-first over the triangle adjacency graph, starting from triangle 0; returns the
    triangles and the number flipped.
    """
    from collections import deque

    n = len(tri)
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    owner = np.tile(np.arange(n), 3)
    key = np.sort(directed, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    pairs = order.reshape(-1, 2)  # closed manifold: every edge exactly twice
    a, b = owner[pairs[:, 0]], owner[pairs[:, 1]]
    same = (directed[pairs[:, 0]] == directed[pairs[:, 1]]).all(axis=1)  # same direction: inconsistent
    if not same.any():
        return tri, 0
    neighbours = [[] for _ in range(n)]
    for i, j, s in zip(a, b, same):
        neighbours[i].append((j, s))
        neighbours[j].append((i, s))
    flip = np.zeros(n, bool)
    seen = np.zeros(n, bool)
    seen[0] = True
    queue = deque([0])
    while queue:
        i = queue.popleft()
        for j, s in neighbours[i]:
            if not seen[j]:
                flip[j] = flip[i] ^ s
                seen[j] = True
                queue.append(j)
    out = tri.copy()
    out[flip] = out[flip][:, ::-1]
    return out, int(flip.sum())


def simplify(surf: Surface, edge_mm: float) -> Surface:
    """Decimate to triangles of about ``edge_mm`` (quadric error, volume kept); never refines.

    The triangle count is area / (√3/4 · edge²); TetWild's time grows with it.
    """
    target = int(surf.area / (np.sqrt(3) / 4 * edge_mm ** 2))
    if target >= 0.8 * len(surf.triangles):
        return surf
    poly = surf.polydata().decimate(1.0 - target / len(surf.triangles), volume_preservation=True)
    out = prepare(poly, surf.source)
    return Surface(out.points, out.triangles, surf.source,
                   surf.repairs + [f"simplified {len(surf.triangles)} -> {len(out.triangles)} triangles "
                                   f"(~{edge_mm:g} mm edges; volume {100 * (out.volume / surf.volume - 1):+.2f} %)"])

