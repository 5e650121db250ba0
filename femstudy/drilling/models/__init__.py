"""The drilling load models, one module each; importing this package registers them all
(:mod:`femstudy.drilling.registry`). A new model is a new module here."""

import importlib
import pkgutil

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_module.name}")
