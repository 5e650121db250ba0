"""femstudy's P2 node numbering, read off a scikit-fem vector P2 basis.

scikit-fem numbers the DOFs of ``ElementVector(ElementTetP2())`` node by node: node ``i`` has
DOFs ``3i, 3i+1, 3i+2`` (x, y, z); the mesh vertices come first, then one node per edge. An
element's ten nodes are its vertices 0–3 followed by the mid-edge nodes of its edges
[0,1], [1,2], [0,2], [0,3], [1,3], [2,3].
"""

from __future__ import annotations

import numpy as np


def p2_layout(basis) -> tuple[np.ndarray, np.ndarray]:
    """(nodes (n, 3) [mm], elements (m, 10) node indices) of a vector P2 basis on tetrahedra.

    Checks the interleaved numbering the exporters rely on: the three DOFs of a node are
    consecutive and share one location.
    """
    dofs = basis.element_dofs
    if dofs.shape[0] != 30 or basis.N % 3:
        raise ValueError(f"expected a 3-component P2 tetrahedral basis, got {dofs.shape[0]} DOFs per element")
    if not (np.array_equal(dofs[1::3], dofs[::3] + 1) and np.array_equal(dofs[2::3], dofs[::3] + 2)
            and not np.any(dofs[::3] % 3)):
        raise ValueError("the basis does not number DOFs node by node (3i, 3i+1, 3i+2)")
    locations = basis.doflocs.T
    nodes = locations[::3]
    if not (np.array_equal(locations[1::3], nodes) and np.array_equal(locations[2::3], nodes)):
        raise ValueError("the three DOFs of a node do not share one location")
    return np.ascontiguousarray(nodes), np.ascontiguousarray(dofs[::3].T // 3)
