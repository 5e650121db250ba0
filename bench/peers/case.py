"""The discrete problem handed to the peer solvers, as plain arrays in one ``.npz``.

Everything is in femstudy's numbering (P2 node ``i`` ↔ DOFs ``3i, 3i+1, 3i+2``) and units
(mm, N, N·mm, MPa, tonne/mm³, s). The file holds only numeric arrays so that the system
Python's older numpy (DOLFINx side) reads it too.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, fields

import numpy as np

from femstudy.atomic import atomic_path
from femstudy.export.calculix import DynamicStep, Isotropic, StaticStep, write_inp


@dataclass
class PeerCase:
    """One mesh, its materials, clamps and loads.

    nodes, elements     : P2 nodes (n, 3) [mm] and elements (m, 10) in scikit-fem's layout
    region              : (m,) region code per element
    material_codes      : (r,) region codes with E [MPa], ν [-], ρ [tonne/mm³] alongside
    fixed_nodes         : nodes held in x, y and z
    thrust, torque      : unit load vectors (3n,): 1 N of thrust and 1 N·mm of torque, assembled
    static_thrust_N, static_torque_Nmm : the static load  f = F·thrust + T·torque
    times_s, thrust_N, torque_Nmm      : the transient load history on a uniform time grid
    drill_node          : node at the drill entry point (deflection history)
    watch_nodes         : nodes whose transient displacements peers write (the surface)
    """

    nodes: np.ndarray
    elements: np.ndarray
    region: np.ndarray
    material_codes: np.ndarray
    youngs_modulus_MPa: np.ndarray
    poissons_ratio: np.ndarray
    density_t_mm3: np.ndarray
    fixed_nodes: np.ndarray
    thrust: np.ndarray
    torque: np.ndarray
    static_thrust_N: float
    static_torque_Nmm: float
    times_s: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray
    drill_node: int
    watch_nodes: np.ndarray

    @property
    def n_dofs(self) -> int:
        return 3 * len(self.nodes)

    @property
    def static_force(self) -> np.ndarray:
        """f = F·thrust + T·torque [N]."""
        return self.static_thrust_N * self.thrust + self.static_torque_Nmm * self.torque

    @property
    def dt_s(self) -> float:
        return float(self.times_s[1] - self.times_s[0])

    def materials(self) -> dict[int, Isotropic]:
        return {int(c): Isotropic(float(e), float(nu), float(rho)) for c, e, nu, rho in
                zip(self.material_codes, self.youngs_modulus_MPa, self.poissons_ratio, self.density_t_mm3)}

    def save(self, path: str | os.PathLike) -> None:
        """Write the arrays (and ``static_force``, which the DOLFINx runner reads) atomically."""
        arrays = {f.name: np.asarray(getattr(self, f.name)) for f in fields(self)}
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, static_force=self.static_force, **arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "PeerCase":
        with np.load(path) as data:
            values = {f.name: data[f.name] for f in fields(cls)}
        for name in ("static_thrust_N", "static_torque_Nmm"):
            values[name] = float(values[name])
        values["drill_node"] = int(values["drill_node"])
        return cls(**values)


def write_calculix(case: PeerCase, path: str | os.PathLike, analysis: str) -> None:
    """The case as a CalculiX deck: ``static`` (one *STATIC step, all nodes written) or
    ``transient`` (one *DYNAMIC step over the load history, watch nodes written)."""
    common = dict(nodes=case.nodes, elements=case.elements, region=case.region,
                  materials=case.materials(), fixed_nodes=case.fixed_nodes)
    if analysis == "static":
        write_inp(path, steps=[StaticStep(case.static_force)], **common)
    elif analysis == "transient":
        step = DynamicStep(patterns=[case.thrust, case.torque], times_s=case.times_s - case.times_s[0],
                           amplitudes=[case.thrust_N, case.torque_Nmm], dt_s=case.dt_s,
                           duration_s=float(case.times_s[-1] - case.times_s[0]))
        write_inp(path, steps=[step], output_nodes=case.watch_nodes, **common)
    else:
        raise ValueError(f"unknown analysis {analysis!r}")
