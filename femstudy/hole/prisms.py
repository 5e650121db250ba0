"""Split triangular prisms into tetrahedra so that neighbouring prisms conform.

A prism (v0, v1, v2 | v3, v4, v5), v3 over v0, v4 over v1, v5 over v2, has three
quadrilateral faces. Each is cut along the diagonal through its vertex of smallest global
index, so two prisms sharing a face cut it the same way; with that rule a prism always splits
into three tetrahedra (Dompierre, Labbé, Vallet & Camarero 1999, "How to subdivide pyramids,
prisms and hexahedra into tetrahedra", Tables 1–2): rotate the prism until its smallest
vertex is v0, then

    min(v1, v5) < min(v2, v4):  (v0 v1 v2 v5), (v0 v1 v5 v4), (v0 v4 v5 v3)
    otherwise:                  (v0 v1 v2 v4), (v0 v4 v2 v5), (v0 v4 v5 v3).

Prisms whose vertical edges have collapsed (a vertex repeated) are split by the same rule
and the tetrahedra with a repeated vertex dropped; the rest still fill the cell and still
conform, because every collapsed quadrilateral is a triangle on both sides.
"""

from __future__ import annotations

import numpy as np

#: For each position of the smallest vertex, the prism symmetry that moves it to v0.
_ROTATE = np.array([[0, 1, 2, 3, 4, 5], [1, 2, 0, 4, 5, 3], [2, 0, 1, 5, 3, 4],
                    [3, 5, 4, 0, 2, 1], [4, 3, 5, 1, 0, 2], [5, 4, 3, 2, 1, 0]])
_SPLIT_A = np.array([[0, 1, 2, 5], [0, 1, 5, 4], [0, 4, 5, 3]])
_SPLIT_B = np.array([[0, 1, 2, 4], [0, 4, 2, 5], [0, 4, 5, 3]])


def split_prisms(prisms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tetrahedra of prisms by the minimum-index rule.

    Parameters
    ----------
    prisms : (n, 6) global vertex indices (v0, v1, v2 | v3, v4, v5), v3 over v0 etc.

    Returns
    -------
    tets : (k, 4) vertex indices, unoriented, without tetrahedra that repeat a vertex
    owner : (k,) the prism of every tetrahedron

    Examples
    --------
    >>> tets, owner = split_prisms(np.array([[0, 1, 2, 3, 4, 5]]))
    >>> tets.tolist()
    [[0, 1, 2, 5], [0, 1, 5, 4], [0, 4, 5, 3]]
    """
    prisms = np.asarray(prisms)
    rotated = np.take_along_axis(prisms, _ROTATE[np.argmin(prisms, axis=1)], axis=1)
    first = np.minimum(rotated[:, 1], rotated[:, 5]) < np.minimum(rotated[:, 2], rotated[:, 4])
    pattern = np.where(first[:, None, None], _SPLIT_A, _SPLIT_B)  # (n, 3, 4)
    tets = np.take_along_axis(rotated[:, None, :], pattern.reshape(len(prisms), 1, 12), axis=2).reshape(-1, 4)
    owner = np.repeat(np.arange(len(prisms)), 3)
    s = np.sort(tets, axis=1)
    distinct = (np.diff(s, axis=1) > 0).all(axis=1)
    return tets[distinct], owner[distinct]
