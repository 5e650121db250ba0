"""The local frame of a drilled hole: entry point, drill axis and two axes across it.

Local coordinates of a point x are (x₁, x₂, ζ) = ((x − o)·e1, (x − o)·e2, (x − o)·d): ζ is
the depth along the drill axis d below the entry point o [mm].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from femstudy.errors import require
from femstudy.fe.materials import frame_with_axis


@dataclass(frozen=True)
class HoleFrame:
    """origin o [mm], unit drill axis d (into the bone), unit e1, e2 with (e1, e2, d) right-handed."""

    origin: np.ndarray
    axis: np.ndarray
    e1: np.ndarray
    e2: np.ndarray

    @classmethod
    def along(cls, origin, axis) -> "HoleFrame":
        """The frame at ``origin`` with drill axis ``axis`` (any length) and e1, e2 chosen ⟂ to it.

        Parameters
        ----------
        origin : (3,) entry point [mm]
        axis : (3,) drill direction, into the bone

        Returns
        -------
        :class:`HoleFrame`

        Examples
        --------
        >>> f = HoleFrame.along([0, 0, 0], [0, 0, 2])
        >>> f.axis.tolist()
        [0.0, 0.0, 1.0]
        """
        axis = np.asarray(axis, float)
        require(axis.shape == (3,) and np.linalg.norm(axis) > 0, f"the drill axis must be a non-zero 3-vector, got {axis}")
        R = frame_with_axis(axis)
        return cls(np.asarray(origin, float), R[:, 2], R[:, 0], R[:, 1])

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) matrix with columns e1, e2, d."""
        return np.column_stack([self.e1, self.e2, self.axis])

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) local (x₁, x₂, ζ) [mm] of global points (n, 3)."""
        return (np.asarray(points, float) - self.origin) @ self.rotation

    def to_global(self, local: np.ndarray) -> np.ndarray:
        """(n, 3) global points of local coordinates (n, 3) [mm]."""
        return self.origin + np.asarray(local, float) @ self.rotation.T

    def radial(self, points: np.ndarray) -> np.ndarray:
        """(n,) distance from the drill axis [mm]."""
        local = self.to_local(points)
        return np.hypot(local[:, 0], local[:, 1])
