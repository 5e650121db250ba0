"""Mesh-convergence and parameter sweeps."""
