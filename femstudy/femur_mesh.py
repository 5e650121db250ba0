"""The data that meshing hands to the solver: a region-marked tet mesh and its landmarks.

Units: mm. Region codes are small integers stored per tetrahedron; the medullary canal is
empty space and has no code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CORTICAL = 1
CANCELLOUS_PROXIMAL = 2
CANCELLOUS_DISTAL = 3
REGION_NAMES = {CORTICAL: "cortical", CANCELLOUS_PROXIMAL: "cancellous_proximal",
                CANCELLOUS_DISTAL: "cancellous_distal"}


@dataclass(frozen=True)
class TetMesh:
    """Linear tetrahedra with a region code per cell.

    points : (n, 3) float64 coordinates [mm]
    tets   : (m, 4) int64 vertex indices, positively oriented (det > 0)
    region : (m,) int8 region code (CORTICAL, CANCELLOUS_PROXIMAL, CANCELLOUS_DISTAL)
    """

    points: np.ndarray
    tets: np.ndarray
    region: np.ndarray

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def n_tets(self) -> int:
        return len(self.tets)


@dataclass(frozen=True)
class DrillSite:
    """Where and how the drill enters the bone.

    entry_point            : (3,) point on the outer surface [mm]
    outward_normal         : (3,) unit outward surface normal at the entry point
    direction              : (3,) unit drill axis, pointing into the bone
    cortical_thickness_mm  : cortex crossed along the drill axis from the entry point [mm]
    beyond_cortex          : what the drill meets past the cortex: "canal" (no bone) or
                             "cancellous" bone
    """

    name: str
    entry_point: np.ndarray
    outward_normal: np.ndarray
    direction: np.ndarray
    cortical_thickness_mm: float
    beyond_cortex: str = "canal"


@dataclass(frozen=True)
class Clamps:
    """Boolean masks over mesh points: the surface nodes held fixed at each end."""

    proximal: np.ndarray
    distal: np.ndarray

    @property
    def any(self) -> np.ndarray:
        """Mask of every clamped point."""
        return self.proximal | self.distal
