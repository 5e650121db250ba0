"""Exports of a femstudy model to other finite-element programs."""
