"""Shared models for the hole tests: flat plates drilled along z, and the exact elastic fields
of a plate with a circular hole (Kirsch) and of a thick-walled cylinder (Lamé).

Models are cached per process so several tests share one mesh and one assembly. Material:
the thesis's isotropic cortical bone (E = 16 GPa, ν = 0.4), the default of MaterialsSpec.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from femstudy.casefile import MaterialsSpec
from femstudy.fe import assemble
from femstudy.hole import HoleFrame, Resolution, hole_mesh

E_MPA, NU = 16e3, 0.4
MU = E_MPA / (2 * (1 + NU))
KAPPA = 3 - 4 * NU  # plane strain
DIAMETER, POINT_ANGLE = 2.7, 90.0
RADIUS = DIAMETER / 2
CONE = RADIUS / np.tan(np.radians(POINT_ANGLE) / 2)


def assemble_model(mesh, order: int):
    """The one place the tests turn a mesh into an FE system (materials: Table 3-1 cortex)."""
    return assemble(mesh, MaterialsSpec().to_fe(), order=order)


@lru_cache(maxsize=None)
def plate(thickness: float, tips: tuple, refinement: float = 1.0, submodel_radius: float = 8.0,
          n_wall: int = 24):
    """A plate 0 ≤ ζ ≤ thickness around a hole drilled along +z from the origin."""
    return hole_mesh(HoleFrame.along([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), DIAMETER, POINT_ANGLE, submodel_radius,
                     list(tips), top=lambda xy: np.zeros(len(xy)),
                     bottom=lambda xy: (np.full(len(xy), thickness), np.ones(len(xy), bool)),
                     resolution=Resolution(refinement=refinement, n_wall=n_wall))


def inner_cortex(xy: np.ndarray) -> np.ndarray:
    """ζ_I [mm] of the layered plate's cortical–cancellous interface, gently tilted and curved."""
    return 3.3 + 0.08 * xy[:, 0] + 0.03 * xy[:, 1] ** 2


@lru_cache(maxsize=None)
def layered_plate(follow: bool = True, refinement: float = 1.0):
    """An 8 mm plate around a hole drilled along +z to tips 2, 4, 6 mm: cortex above
    :func:`inner_cortex`, cancellous bone below; ``follow``: the mesh's layers follow it."""
    from femstudy.femur_mesh import CANCELLOUS_DISTAL, CORTICAL

    frame = HoleFrame.along([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])

    def region(points):
        local = frame.to_local(points)
        return np.where(local[:, 2] < inner_cortex(local[:, :2]), CORTICAL, CANCELLOUS_DISTAL)

    return hole_mesh(frame, DIAMETER, POINT_ANGLE, 6.0, [2.0, 4.0, 6.0], top=lambda xy: np.zeros(len(xy)),
                     bottom=lambda xy: (np.full(len(xy), 8.0), np.ones(len(xy), bool)), region=region,
                     resolution=Resolution(refinement=refinement), interface=inner_cortex if follow else None)


@lru_cache(maxsize=None)
def station_system(thickness: float, tips: tuple, k: int, order: int, refinement: float = 1.0,
                   submodel_radius: float = 8.0):
    station = plate(thickness, tips, refinement, submodel_radius).at_station(k)
    return station, assemble_model(station.mesh, order)


def kirsch_displacement(x: np.ndarray, y: np.ndarray, remote_MPa: float = 1.0, a: float = RADIUS):
    """Plane-strain displacement [mm] around a traction-free hole of radius a under remote
    uniaxial tension along x (Kirsch; e.g. Barber, Elasticity, §8.4.1):
    u_r = σ/(4μ) [r((κ−1)/2 + cos 2θ) + a²/r (1 + (1+κ) cos 2θ) − a⁴/r³ cos 2θ],
    u_θ = σ/(4μ) [(1−κ) a²/r − r − a⁴/r³] sin 2θ."""
    r, t = np.hypot(x, y), np.arctan2(y, x)
    c = remote_MPa / (4 * MU)
    ur = c * (r * ((KAPPA - 1) / 2 + np.cos(2 * t)) + a * a / r * (1 + (1 + KAPPA) * np.cos(2 * t))
              - a ** 4 / r ** 3 * np.cos(2 * t))
    ut = c * ((1 - KAPPA) * a * a / r - r - a ** 4 / r ** 3) * np.sin(2 * t)
    return ur * np.cos(t) - ut * np.sin(t), ur * np.sin(t) + ut * np.cos(t)


def kirsch_stress(x: np.ndarray, y: np.ndarray, remote_MPa: float = 1.0, a: float = RADIUS) -> np.ndarray:
    """(n, 6) Voigt stress [MPa] of the Kirsch field (σzz = ν(σxx + σyy), plane strain)."""
    r, t = np.hypot(x, y), np.arctan2(y, x)
    s = remote_MPa / 2
    srr = s * (1 - a * a / r ** 2) + s * (1 - 4 * a * a / r ** 2 + 3 * a ** 4 / r ** 4) * np.cos(2 * t)
    stt = s * (1 + a * a / r ** 2) - s * (1 + 3 * a ** 4 / r ** 4) * np.cos(2 * t)
    srt = -s * (1 + 2 * a * a / r ** 2 - 3 * a ** 4 / r ** 4) * np.sin(2 * t)
    c, n = np.cos(t), np.sin(t)
    sxx = srr * c * c + stt * n * n - 2 * srt * n * c
    syy = srr * n * n + stt * c * c + 2 * srt * n * c
    sxy = (srr - stt) * n * c + srt * (c * c - n * n)
    zero = np.zeros_like(sxx)
    return np.column_stack([sxx, syy, NU * (sxx + syy), zero, zero, sxy])


def lame(r: np.ndarray, pressure_MPa: float, a: float, b: float):
    """Thick-walled cylinder a ≤ r ≤ b under internal pressure p, plane strain (Lamé):
    σ_rr = A − B/r², σ_θθ = A + B/r², A = p a²/(b² − a²), B = p a² b²/(b² − a²),
    u_r = [(1 − 2ν) A r + B/r] / (2μ). Returns (σ_rr, σ_θθ [MPa], u_r [mm])."""
    A = pressure_MPa * a * a / (b * b - a * a)
    B = A * b * b
    return A - B / r ** 2, A + B / r ** 2, ((1 - 2 * NU) * A * r + B / r) / (2 * MU)
