"""matplotlib for files: pyplot on the Agg backend (no display) and an atomic save."""

from __future__ import annotations

from femstudy import atomic

#: Resolution of the study's, the recordings' and the load models' figures [dots per inch].
DPI = 130


def pyplot():
    """matplotlib's pyplot on the Agg backend (files only, no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path) -> None:
    """Save ``fig`` at ``path`` atomically, in the format its suffix names, and close it."""
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI, format=str(path).rsplit(".", 1)[-1].lower())
    pyplot().close(fig)
