"""The drilling load models, one module each; importing this package registers them all
(:mod:`femstudy.drilling.registry`). A new model is a new module here."""

from femstudy.plugins import import_modules

import_modules(__name__, __path__)
