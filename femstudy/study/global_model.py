"""The first stage of every study, sweep point and benchmark: a case's femur meshed, assembled
and ready to load (:func:`prepare` → :class:`GlobalModel`).

The model is the femur's tet mesh (cached, :mod:`femstudy.meshing`) with the case's materials
assembled into K and M (:func:`femstudy.fe.assemble`), the drill's surface patch at the site
(its unit thrust and torque patterns, :func:`femstudy.fe.drill_patch`), the clamps at both
ends, and the output channels every analysis reads (deflection, drill point, von Mises with
masks away from the drill and the clamps, per region). Units: mm, N, N·mm, MPa, s.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import partial
from os import PathLike
from pathlib import Path

import numpy as np

from femstudy import fe
from femstudy.casefile import Case
from femstudy.femur_mesh import REGION_NAMES
from femstudy.kept_answers import kept_answer
from femstudy.meshing import FemurModel
from femstudy.meshing.cache import DEFAULT_CACHE_DIR
from femstudy.study.femur import femur_model


@dataclass(frozen=True, eq=False)
class GlobalModel:
    """A case's femur, assembled and ready to load.

    case : the case it was built from
    femur : the meshed femur (mesh, clamps, drill site, frame, quality, statistics)
    system : K and M assembled on the femur's mesh
    patch : the drill's surface patch (unit thrust and torque patterns)
    channels : output channels (:func:`study_channels`)
    mesh_s, assembly_s : wall times of meshing (or reading the cache) and of assembly [s]
    """

    case: Case
    femur: FemurModel
    system: fe.FESystem
    patch: fe.DrillPatch
    channels: tuple
    mesh_s: float
    assembly_s: float

    def clamped(self, case: Case) -> "GlobalModel":
        """This model under ``case``'s clamps (a copy of this case with another clamp length): the
        same mesh and stiffness, other clamped nodes and output masks."""
        from femstudy.meshing import landmarks

        femur = self.femur
        clamps = landmarks.clamps(femur.mesh, femur.frame, landmarks.outer_faces(femur.mesh, femur.frame),
                                  case.clamps.length_mm)
        femur = replace(femur, clamps=clamps)
        channels = study_channels(self.system, self.patch, femur, case.analysis.exclusion_radius_mm,
                                  case.clamps.length_mm)
        return replace(self, case=case, femur=femur, channels=channels)

    def factorize(self, solver: str = "auto", keep: str | PathLike | None = None) -> fe.FactorizedSystem:
        """K_ff under the femur's clamps, factorised (or served by solutions kept in ``keep``,
        :mod:`femstudy.fe.kept`)."""
        return fe.factorize(self.system, fe.clamp(self.system, self.femur.clamps), solver,
                            keep=None if keep is None else Path(keep))


def study_channels(system, patch, femur, exclusion_radius_mm: float, clamp_length_mm: float) -> tuple:
    """The output points of a study: every node's |u|, the drill point's mean displacement,
    and every stress point's von Mises stress, with masks for the points more than the
    exclusion radius from the drill point and from the clamped ends, and per region."""
    from femstudy.fe.post import quadrature_points

    points = quadrature_points(system)
    nq = points.shape[1]
    points = points.reshape(-1, 3)
    heights = points @ femur.frame.up
    nodes_up = system.nodes @ femur.frame.up
    margin = clamp_length_mm + exclusion_radius_mm
    away = ((np.linalg.norm(points - patch.centre, axis=1) > exclusion_radius_mm)
            & (heights < nodes_up.max() - margin) & (heights > nodes_up.min() + margin))
    masks = {"outside": away}
    for code, name in REGION_NAMES.items():
        masks[name] = np.repeat(system.region == code, nq)
    return (fe.deflection_channel(system), fe.point_channel("drill_point", patch.mean, patch.centre),
            fe.von_mises_channel(system, masks))


#: Largest assembled system kept [bytes of its matrices]: the default femur's (8 mm, 174k DOFs)
#: is 0.14 GB, read back in 0.1 s against 1 s to assemble; a finer mesh's would fill the cache
#: faster than it saves time.
MAX_KEPT_ASSEMBLY_BYTES = 2 ** 30


#: Assemblies kept in a cache at most (the newest): every code change keys a new one.
KEPT_ASSEMBLIES = 4


def _read_back(system: fe.FESystem) -> fe.FESystem:
    """A kept assembly says so: its phase times were another run's (summary.json's
    ``solver.assembly``; this run's reading time is ``timings.assembly_s``)."""
    return replace(system, timings={"kept_from_earlier_run": True})


def _small_enough(system: fe.FESystem) -> bool:
    matrices = (system.K_blocks.data, system.K_blocks.indices, system.M_nodes.data, system.M_nodes.indices)
    return sum(a.nbytes for a in matrices) <= MAX_KEPT_ASSEMBLY_BYTES


def prepare(case: Case, cache_dir: str | PathLike = DEFAULT_CACHE_DIR, keep_assembly: bool = False) -> GlobalModel:
    """Mesh (or read from the cache) and assemble the femur of ``case``.

    Parameters
    ----------
    case : Case
    cache_dir : str or PathLike
        Mesh cache folder.
    keep_assembly : bool
        Keep the assembled system among the cache's answers (:mod:`femstudy.kept_answers`,
        keyed by the mesh, materials, element order, bone axis and code) and read it from
        there when an earlier run kept it: 0.1 s instead of 1 s for the default femur.

    Returns
    -------
    GlobalModel

    Examples
    --------
    >>> model = prepare(load_case("cases/middiaphysis.toml"))        # doctest: +SKIP
    >>> model.system.n_dofs                                           # doctest: +SKIP
    181911
    """
    start = time.perf_counter()
    femur = femur_model(case, Path(cache_dir))
    meshed = time.perf_counter()
    materials, axis = case.materials.to_fe(), np.asarray(femur.frame.up, float)
    assemble = partial(fe.assemble, femur.mesh, materials, order=case.mesh.order, long_axis=axis)
    system = kept_answer(Path(cache_dir) / "answers", "assembly", (femur.mesh, materials, case.mesh.order, axis),
                         assemble, mark_kept=_read_back, worth_keeping=_small_enough,
                         newest=KEPT_ASSEMBLIES) if keep_assembly else assemble()
    patch = fe.drill_patch(system, femur.site, radius_mm=case.drill.diameter_mm / 2)
    channels = study_channels(system, patch, femur, case.analysis.exclusion_radius_mm, case.clamps.length_mm)
    return GlobalModel(case, femur, system, patch, channels, meshed - start, time.perf_counter() - meshed)
