"""Benchmarks and heavy measurements (not part of the installed package)."""
