"""Readers and writers of the file formats a recording may come in, one module per format;
importing this package registers them all (:mod:`~femstudy.recordings.formats.registry`).

Each reader returns a :class:`~femstudy.recordings.formats.table.Table`; each writer takes the
path, the columns as (quantity, unit, values) and the metadata.
"""

import importlib
import pkgutil

for _module in pkgutil.iter_modules(__path__):
    if _module.name not in ("registry", "table"):
        importlib.import_module(f"{__name__}.{_module.name}")
