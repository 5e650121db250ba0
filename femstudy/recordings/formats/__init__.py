"""Readers and writers of the file formats a recording may come in, one module per format;
importing this package registers them all (:mod:`~femstudy.recordings.formats.registry`).

Each reader returns a :class:`~femstudy.recordings.formats.table.Table`; each writer takes the
path, the columns as (quantity, unit, values) and the metadata.
"""

from femstudy.plugins import import_modules

import_modules(__name__, __path__, skip=("registry", "table"))
