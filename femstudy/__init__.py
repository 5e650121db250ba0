"""femstudy: finite-element studies of the femur under surgical-drilling loads.

Units inside the package are mm, N, N·mm, MPa, s and tonne/mm³; other units are accepted
only at the edges (readers, command line) and converted explicitly there.

The public API (each returns a documented result object; docs/examples/ uses them)::

    case = femstudy.load_case("cases/middiaphysis.toml")
    result = femstudy.run_study(case, "results/mid")           # StudyResult
    model = femstudy.prepare(case)                             # GlobalModel: the femur meshed and assembled
    loading = femstudy.case_loading(case, model.femur.site.cortical_thickness_mm)   # CaseLoading
    sweep = femstudy.sweep("cases/middiaphysis.toml", [16, 12, 8])   # SweepResult
    cal = femstudy.calibrate(["demo/calibration"], name="mybone")    # CalibrationResult
    d = femstudy.diagnose(recording, simulation)                # Diagnosis

and the layers below them: :mod:`femstudy.drilling` (load models), :mod:`femstudy.meshing`
(femur meshes), :mod:`femstudy.fe` (finite elements), :mod:`femstudy.recordings`. Messages
go to the ``femstudy`` logger; configuration (cache folder, solver, bone library) is passed
as parameters. Names are imported on first use, so ``import femstudy`` stays light.
"""

from importlib import import_module

__version__ = "0.1.0"

#: public name → module that defines it
_API = {
    "load_case": "femstudy.casefile", "parse_case": "femstudy.casefile", "Case": "femstudy.casefile",
    "run_study": "femstudy.study.run", "StudyResult": "femstudy.study.study_result",
    "prepare": "femstudy.study.global_model", "GlobalModel": "femstudy.study.global_model",
    "case_loading": "femstudy.study.loading", "CaseLoading": "femstudy.study.loading",
    "run_cases": "femstudy.study.study",
    "mesh_case": "femstudy.study.femur", "femur_model": "femstudy.study.femur",
    "write_femur": "femstudy.meshing.builtin_femur", "FemurParameters": "femstudy.meshing.builtin_femur",
    "sweep": "femstudy.sweeps.run", "SweepResult": "femstudy.sweeps.run",
    "run_uncertainty": "femstudy.uncertainty.run", "UncertaintyResult": "femstudy.uncertainty.result",
    "calibrate": "femstudy.recordings.workflow", "CalibrationResult": "femstudy.recordings.pipeline",
    "read_recording": "femstudy.recordings.reader", "Recording": "femstudy.recordings.reader",
    "write_recording": "femstudy.recordings.reader", "synthesize": "femstudy.recordings.synthetic",
    "write_dataset": "femstudy.recordings.dataset",
    "diagnose": "femstudy.diagnosis", "Diagnosis": "femstudy.diagnosis",
    "BoneMaterials": "femstudy.materials", "IsotropicMaterial": "femstudy.materials",
    "UserError": "femstudy.errors",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        value = getattr(import_module(_API[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'femstudy' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
