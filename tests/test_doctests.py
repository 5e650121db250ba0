"""The examples in the package's docstrings run (those marked ``doctest: +SKIP`` need a femur
mesh or a file and are shown, not run)."""

import doctest
import importlib
import pkgutil

import pytest

import femstudy

MODULES = sorted(m.name for m in pkgutil.walk_packages(femstudy.__path__, "femstudy.")
                 if not m.name.startswith("femstudy.commands") and m.name != "femstudy.__main__")


def with_examples() -> list[str]:
    found = []
    for name in MODULES:
        module = importlib.import_module(name)
        finder = doctest.DocTestFinder()
        if any(t.examples for t in finder.find(module)):
            found.append(name)
    return found


@pytest.mark.parametrize("name", with_examples())
def test_docstring_examples_run(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # examples that write files write them here
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False,
                             extraglobs={"np": __import__("numpy")})
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"
