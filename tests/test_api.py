"""The public API (femstudy.__all__): names that are what they say, paths as str or PathLike."""

import importlib
import pkgutil
import types

import femstudy
from conftest import REPO
from femstudy.casefile import with_overrides


def test_no_public_name_is_shadowed_by_a_module():
    """Importing every module of the package (as a script that uses femstudy.fe would) leaves
    each public name the function or class it documents, never a module of that name."""
    for info in pkgutil.walk_packages(femstudy.__path__, "femstudy."):
        if info.name != "femstudy.__main__":
            importlib.import_module(info.name)
    for name in femstudy.__all__:
        value = getattr(femstudy, name)
        assert not isinstance(value, types.ModuleType), f"femstudy.{name} is a module"
    assert callable(femstudy.femur_model) and callable(femstudy.prepare)


def test_paths_may_be_given_as_strings(tmp_path, shared_cache):
    case = femstudy.load_case(str(REPO / "cases" / "middiaphysis.toml"))
    model = femstudy.mesh_case(case, str(tmp_path / "mesh"), mesh_size_mm=16, cache_dir=str(shared_cache))
    assert (tmp_path / "mesh" / "mesh.vtu").is_file() and model.mesh.n_tets > 0
    assert femstudy.prepare(with_overrides(case, {"mesh.size_mm": 16.0}), str(shared_cache)).system.n_dofs > 0
