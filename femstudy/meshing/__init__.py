"""Femur geometry and meshing: a surface in, a region-marked tet mesh with landmarks out.

``build_femur_model(spec, cache_dir, mesh_size_mm=None)`` turns a :class:`FemurSpec` into a
:class:`FemurModel`:

* ``mesh``    :class:`~femstudy.femur_mesh.TetMesh` [mm], positively oriented tets with
  region codes CORTICAL, CANCELLOUS_PROXIMAL, CANCELLOUS_DISTAL (the canal has no tets);
* ``clamps``  :class:`~femstudy.femur_mesh.Clamps`, outer-surface nodes near each end;
* ``site``    :class:`~femstudy.femur_mesh.DrillSite`;
* ``frame``   :class:`~femstudy.meshing.frame.Frame`, units, axes, side, length, overrides;
* ``quality`` dihedral angles, radius-ratio distribution and poor-tet count;
* ``stats``   sizes, per-region tets and volumes, surface and canal volumes, TetWild time,
  ``cache_hit`` and ``cache_key``.

Modules: :mod:`.builtin_femur` (the default bone), :mod:`.surface` (reading and checking),
:mod:`.frame` (units and anatomical axes), :mod:`.bone_ends` (femoral head and condyles),
:mod:`.spheres` (sphere fit and spherical caps), :mod:`.regions` (cortex, canal, cancellous),
:mod:`.tetra` (TetWild, classification, quality), :mod:`.landmarks`, :mod:`.cache`,
:mod:`.report` (files and the cut-away picture). docs/meshing.md explains the choices.
"""

from femstudy.meshing.model import FemurModel, FemurSpec, build_femur_model

__all__ = ["FemurModel", "FemurSpec", "build_femur_model"]
