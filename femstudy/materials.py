"""Material records the solver takes: plain values in MPa and tonne/mm³, no file schema.

Case files describe materials in the thesis tables' units (GPa, kg/m³) and convert to these
records (:meth:`femstudy.casefile.MaterialsSpec.to_fe`); scripts may build them directly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from femstudy import thesis


@dataclass(frozen=True)
class IsotropicMaterial:
    """Young's modulus E [MPa], Poisson's ratio ν and density ρ [tonne/mm³]."""

    E_MPa: float
    nu: float
    density_t_mm3: float


def _table_3_1(name: str) -> IsotropicMaterial:
    return IsotropicMaterial(**thesis.TABLE_3_1[name])


@dataclass(frozen=True)
class BoneMaterials:
    """The materials of the femur's regions: cortical bone, and cancellous bone for both
    cancellous regions. ``cortical_model = "transversely_isotropic"`` replaces the cortical
    elastic constants by :data:`femstudy.fe.materials.CORTICAL_TRANSVERSELY_ISOTROPIC`
    about the long axis (its density stays). Defaults: thesis Table 3-1."""

    cortical: IsotropicMaterial = field(default_factory=lambda: _table_3_1("cortical"))
    cancellous: IsotropicMaterial = field(default_factory=lambda: _table_3_1("cancellous"))
    cortical_model: Literal["isotropic", "transversely_isotropic"] = "isotropic"
