"""Which tetrahedron of a mesh holds each point of a line: a drill axis sampled from its entry.

The study asks this of the drill axis three times (the cortex crossed, what lies past it, the
bone along the drilled depth), on the critical path of every run. pyvista's cell locator
answers it too, but importing pyvista's core for it costs 0.3 s of a cached study's 5 s. Here
the tets whose bounding boxes the segment crosses (a slab test, one pass over the tets) are the
candidates, and each sample's barycentric coordinates in them decide, exactly as a locator's
final test does (tests/test_meshing.py compares with pyvista's on both femurs).
"""

from __future__ import annotations

import numpy as np

from femstudy.femur_mesh import TetMesh

#: A point this far outside a tet (in barycentric coordinates) still counts as inside it: a
#: point on a face shared by two tets lies in one of them.
TOLERANCE = 1e-10


def cells_along(mesh: TetMesh, start, direction, distances) -> np.ndarray:
    """The index of a tet of ``mesh`` containing start + s·direction for each s of
    ``distances`` [mm] (the lowest index where several share the point), −1 outside the mesh.

    Examples
    --------
    >>> from femstudy.fe.geometry import tube_mesh
    >>> tube = tube_mesh(40.0, 10.0, 6.0, 2, 16, 8)
    >>> cells = cells_along(tube, [-20.0, 0.0, 20.0], [1.0, 0.0, 0.0], [1.0, 12.0, 20.0, 28.0])
    >>> (cells >= 0).tolist()   # in the air, the wall, the bore, the far wall
    [False, True, False, True]
    """
    start, direction = np.asarray(start, float), np.asarray(direction, float)
    s = np.atleast_1d(np.asarray(distances, float))
    corners = mesh.points[mesh.tets]                                   # (n, 4, 3)
    enter, leave = _slabs(corners.min(axis=1), corners.max(axis=1), start, direction, s.min(), s.max())
    candidates = np.flatnonzero(enter <= leave)
    # the samples within each candidate's stretch of the line [enter, leave]: (candidate, sample) pairs
    order = np.argsort(s, kind="stable")
    first = np.searchsorted(s[order], enter[candidates], "left")
    counts = np.searchsorted(s[order], leave[candidates], "right") - first
    owner = np.repeat(np.arange(candidates.size), counts)
    sample = order[np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(first, counts)]
    # barycentric λ1..3 of each sample in its candidate: (v1 − v0, v2 − v0, v3 − v0) λ = x − v0
    origin = corners[candidates, 0]
    inverse = np.linalg.inv(np.swapaxes(corners[candidates, 1:] - origin[:, None], 1, 2))
    lam = np.einsum("pij,pj->pi", inverse[owner], start + np.outer(s[sample], direction) - origin[owner])
    inside = (lam >= -TOLERANCE).all(axis=1) & (lam.sum(axis=1) <= 1 + TOLERANCE)
    none = np.iinfo(np.int64).max  # no tet yet: above every index, so the lowest one found wins
    found = np.full(s.size, none)
    np.minimum.at(found, sample[inside], candidates[owner[inside]])
    found[found == none] = -1
    return found


def _slabs(lo: np.ndarray, hi: np.ndarray, start: np.ndarray, direction: np.ndarray, s0: float,
           s1: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the segment start + s·direction, s in [s0, s1], enters and leaves each box [lo, hi]
    (slab test; enter > leave: it misses the box)."""
    enter, leave = np.full(len(lo), s0), np.full(len(lo), s1)
    for axis in range(3):
        d = direction[axis]
        if abs(d) < 1e-300:   # parallel to the slab: inside it or never
            outside = (start[axis] < lo[:, axis] - TOLERANCE) | (start[axis] > hi[:, axis] + TOLERANCE)
            leave[outside] = -np.inf
            continue
        a, b = (lo[:, axis] - TOLERANCE - start[axis]) / d, (hi[:, axis] + TOLERANCE - start[axis]) / d
        np.maximum(enter, np.minimum(a, b), out=enter)
        np.minimum(leave, np.maximum(a, b), out=leave)
    return enter, leave
