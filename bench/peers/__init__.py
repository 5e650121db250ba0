"""Peer solvers (CalculiX, DOLFINx) on femstudy's discrete problem, and how they are timed."""
