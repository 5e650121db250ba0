"""Readers and writers of the file formats a recording may come in (one module per format).

Each reader returns a :class:`~femstudy.recordings.formats.table.Table`; each writer takes a
:class:`~femstudy.recordings.reader.Recording` and the column units to write.
"""
