"""TetWild tetrahedralisation, region markers and a mesh quality report.

fTetWild (through pytetwild) meshes the outer surface, the cortex's inner surface and the
canal/cancellous interface together, so every region boundary is made of tet faces. Its own
winding-number filter would be confused by the open canal/cancellous patches, so the whole
background mesh is kept (``disable_filtering``) and each tet is classified here from the
region fields of :mod:`femstudy.meshing.regions`: for a field ψ the tet lies on the side of
the sign of ψ at whichever of its vertices and centroid has the largest |ψ|. A tet that
conforms to an interface has its vertices on that interface (|ψ| ≈ 0, up to the envelope)
or on one side of it, so this vote is not fooled by the interface moving within TetWild's
envelope, as a centroid test would be for flat tets.
"""

from __future__ import annotations

import contextlib
import tempfile
import time

import numpy as np

from femstudy.femur_mesh import CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL, TetMesh


def tetrahedralize(surfaces, size_mm: float, envelope: float, threads: int = 0):
    """fTetWild on the union of triangle surfaces (list of (points, triangles)).

    The surfaces are used as given (fTetWild's own simplification is skipped: they are
    simplified beforehand). Returns points (n, 3), positively oriented tets (m, 4) of the
    whole background mesh, and the wall time [s].
    """
    import pytetwild

    pts, tris, offset = [], [], 0
    for p, t in surfaces:
        pts.append(np.asarray(p, float))
        tris.append(np.asarray(t, np.int64) + offset)
        offset += len(p)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="femstudy-tetwild-") as scratch, contextlib.chdir(scratch):
        # fTetWild may write debugging surfaces (__tracked_surface.stl, ...) to the working folder
        points, tets = pytetwild.tetrahedralize(
            np.concatenate(pts), np.concatenate(tris).astype(np.int32), edge_length_abs=size_mm,
            epsilon=envelope, simplify=False, disable_filtering=True, num_threads=threads, quiet=True)
    seconds = time.perf_counter() - start
    points = np.asarray(points, np.float64)
    return points, orient(points, np.asarray(tets, np.int64)), seconds


def signed_volumes(points, tets) -> np.ndarray:
    """Signed tet volumes V = det[x1 − x0, x2 − x0, x3 − x0] / 6 [mm³]."""
    x = points[tets]
    return np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0])) / 6.0


def orient(points, tets) -> np.ndarray:
    """Swap two vertices of every negatively oriented tet."""
    neg = signed_volumes(points, tets) < 0
    tets = tets.copy()
    tets[neg, 0], tets[neg, 1] = tets[neg, 1], tets[neg, 0].copy()
    return tets


def side_vote(values_at_vertices: np.ndarray, values_at_centroid: np.ndarray) -> np.ndarray:
    """True where the value of largest magnitude among a tet's vertices and centroid is > 0."""
    v = np.column_stack([values_at_vertices, values_at_centroid])
    pick = np.abs(v).argmax(axis=1)
    return v[np.arange(len(v)), pick] > 0


def classify(points, tets, fields, frame, canal_span) -> np.ndarray:
    """Region code per tet (CORTICAL, CANCELLOUS_*), 0 outside the bone or in the canal."""
    centroids = points[tets].mean(axis=1)

    def inside(name):
        at_points = fields.sample(name, points)
        return side_vote(at_points[tets], fields.sample(name, centroids))

    region = np.zeros(len(tets), np.int8)
    bone = inside("depth")
    canal = inside("canal") & bone
    inner = inside("inner") & bone & ~canal
    region[bone & ~canal] = CORTICAL
    mid = 0.5 * (canal_span[0] + canal_span[1])
    proximal = frame.fraction(centroids) < mid
    region[inner & proximal] = CANCELLOUS_PROXIMAL
    region[inner & ~proximal] = CANCELLOUS_DISTAL
    return _manifold_boundary(tets, _largest_component(tets, region))


def _manifold_boundary(tets, region, rounds: int = 10) -> np.ndarray:
    """Fill empty tets around boundary edges shared by more than two boundary faces.

    Where the canal's end meets cancellous bone, two empty pockets can touch along an edge
    of the mesh, pinching the boundary there; the empty tets around such an edge get the
    region most common among the bone tets around it.
    """
    region = region.copy()
    pairs = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    for _ in range(rounds):
        kept = region > 0
        t = tets[kept]
        faces = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]])
        key, counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
        boundary = key[counts == 1]
        edges = np.sort(np.concatenate([boundary[:, [0, 1]], boundary[:, [1, 2]], boundary[:, [0, 2]]]), axis=1)
        e, c = np.unique(edges, axis=0, return_counts=True)
        bad = e[c > 2]
        if len(bad) == 0:
            break
        n = tets.max() + 1
        code = (np.sort(np.concatenate([tets[:, [i, j]] for i, j in pairs]), axis=1) * [n, 1]).sum(axis=1)
        owner = np.tile(np.arange(len(tets)), len(pairs))
        for edge in bad[:, 0] * n + bad[:, 1]:
            around = owner[code == edge]
            solid = region[around][region[around] > 0]
            region[around[region[around] == 0]] = np.bincount(solid).argmax()
    return region


def _largest_component(tets, region) -> np.ndarray:
    """Zero the region of tets not face-connected to the largest piece of bone."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    keep = np.nonzero(region)[0]
    faces = np.sort(np.concatenate([tets[keep][:, [1, 2, 3]], tets[keep][:, [0, 2, 3]],
                                    tets[keep][:, [0, 1, 3]], tets[keep][:, [0, 1, 2]]]), axis=1)
    owner = np.tile(np.arange(len(keep)), 4)
    order = np.lexsort(faces.T[::-1])
    f, o = faces[order], owner[order]
    same = (f[1:] == f[:-1]).all(axis=1)
    a, b = o[:-1][same], o[1:][same]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(len(keep), len(keep)))
    n, labels = connected_components(graph, directed=False)
    if n > 1:
        largest = np.bincount(labels).argmax()
        region = region.copy()
        region[keep[labels != largest]] = 0
    return region


def compact(points, tets, region) -> TetMesh:
    """The TetMesh of tets with a non-zero region, unused points dropped."""
    sel = region > 0
    t = tets[sel]
    used, inverse = np.unique(t, return_inverse=True)
    return TetMesh(points[used].copy(), inverse.reshape(t.shape).astype(np.int64), region[sel].astype(np.int8))


def quality(mesh: TetMesh, poor_radius_ratio: float = 0.1) -> dict:
    """Minimum dihedral angle and normalised radius ratio ρ = 3 r_in / R_circ (1 for a regular tet).

    r_in = 3V / Σ face areas; R_circ from |a²(b×c) + b²(c×a) + c²(a×b)| / (12 V) with a, b, c
    the edge vectors from one vertex. A tet is *poor* if ρ < ``poor_radius_ratio``.
    """
    x = mesh.points[mesh.tets]
    a, b, c = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    faces = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]  # outward for positive tets
    normals = np.stack([np.cross(x[:, j] - x[:, i], x[:, k] - x[:, i]) for i, j, k in faces], axis=1)
    areas = 0.5 * np.linalg.norm(normals, axis=2)
    r_in = 3 * vol / areas.sum(axis=1)
    num = (np.einsum("ij,ij->i", a, a)[:, None] * np.cross(b, c) + np.einsum("ij,ij->i", b, b)[:, None] * np.cross(c, a)
           + np.einsum("ij,ij->i", c, c)[:, None] * np.cross(a, b))
    r_circ = np.linalg.norm(num, axis=1) / (12 * vol)
    rho = 3 * r_in / r_circ
    unit = normals / np.linalg.norm(normals, axis=2, keepdims=True)
    dihedral = [np.degrees(np.pi - np.arccos(np.clip(np.einsum("ij,ij->i", unit[:, i], unit[:, j]), -1, 1)))
                for i in range(4) for j in range(i + 1, 4)]
    dihedral = np.stack(dihedral, axis=1)
    edges = np.stack([np.linalg.norm(x[:, i] - x[:, j], axis=1) for i in range(4) for j in range(i + 1, 4)], axis=1)
    bins = np.linspace(0, 1, 11)
    hist, _ = np.histogram(rho, bins=bins)
    return {
        "n_tets": int(len(rho)),
        "min_volume_mm3": float(vol.min()),
        "min_dihedral_deg": float(dihedral.min()),
        "max_dihedral_deg": float(dihedral.max()),
        "dihedral_deg_p1": float(np.percentile(dihedral.min(axis=1), 1)),
        "radius_ratio_min": float(rho.min()),
        "radius_ratio_percentiles": {str(q): float(np.percentile(rho, q)) for q in (1, 5, 25, 50)},
        "radius_ratio_histogram": {"bin_edges": [round(float(e), 2) for e in bins], "counts": hist.tolist()},
        "poor_radius_ratio_below": poor_radius_ratio,
        "n_poor": int((rho < poor_radius_ratio).sum()),
        "edge_mm": {"min": float(edges.min()), "median": float(np.median(edges)), "max": float(edges.max())},
    }
