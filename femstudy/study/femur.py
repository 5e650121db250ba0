"""The case's femur: its meshing description and the meshed, landmarked model."""

from __future__ import annotations

from pathlib import Path

from femstudy.casefile import Case
from femstudy.meshing import FemurModel, FemurSpec, build_femur_model
from femstudy.meshing.cache import DEFAULT_CACHE_DIR


def femur_spec(case: Case) -> FemurSpec:
    """What meshing needs from a case: surface, geometry, mesh and site sections, the drill's
    radius and the clamped length."""
    return FemurSpec(case.surface_path(), case.geometry, case.mesh, case.site,
                     drill_radius_mm=case.drill.diameter_mm / 2, clamp_length_mm=case.clamps.length_mm)


def femur_model(case: Case, cache_dir: Path = DEFAULT_CACHE_DIR, mesh_size_mm: float | None = None) -> FemurModel:
    """The case's meshed femur (cached in ``cache_dir``); ``mesh_size_mm`` overrides the case's size."""
    return build_femur_model(femur_spec(case), cache_dir, mesh_size_mm)


def mesh_case(case: Case, out_dir: Path | None = None, *, mesh_size_mm: float | None = None,
              cache_dir: Path = DEFAULT_CACHE_DIR) -> FemurModel:
    """Mesh the case's femur (or load it from the cache) and, given ``out_dir``, write the
    mesh, its quality report, frame, landmarks and the cut-away picture there.

    Parameters
    ----------
    case : Case
    out_dir : Path, optional
        Output folder, replaced as a whole.
    mesh_size_mm : float, optional
        Overrides ``case.mesh.size_mm``.
    cache_dir : Path
        Mesh cache folder.

    Returns
    -------
    FemurModel
        ``model.stats["written"]`` lists the files written.

    Examples
    --------
    >>> model = mesh_case(load_case("cases/middiaphysis.toml"), mesh_size_mm=16)   # doctest: +SKIP
    >>> model.mesh.tets.shape                                                      # doctest: +SKIP
    """
    from femstudy import atomic
    from femstudy.errors import require
    from femstudy.meshing.report import write_outputs

    require(mesh_size_mm is None or mesh_size_mm > 0, f"--mesh-size must be positive, got {mesh_size_mm}")
    model = femur_model(case, cache_dir, mesh_size_mm)
    if out_dir is not None:
        with atomic.atomic_folder(Path(out_dir)) as tmp:
            model.stats["written"] = write_outputs(model, tmp, screenshot=case.output.screenshot)
    return model
