"""Figures of recordings, processed runs and calibration results (saved atomically)."""

from __future__ import annotations

import numpy as np

from femstudy import atomic

PHASE_KEYS = (("true_contact_s", "contact"), ("true_full_engagement_s", "full engagement"),
              ("true_breakthrough_s", "breakthrough"), ("true_retraction_s", "retraction"))


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path) -> None:
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130, format=str(path).rsplit(".", 1)[-1].lower())
    pyplot().close(fig)


def plot_recording(path, rec, marks: dict[str, float] | None = None) -> None:
    """Raw thrust and torque against time; phase times (the header's true_* or ``marks``) dashed."""
    plt = pyplot()
    rows = 2 if rec.torque_Nmm is not None else 1
    fig, axes = plt.subplots(rows, 1, figsize=(9, 3.2 * rows + 0.6), sharex=True, constrained_layout=True,
                             squeeze=False)
    axes = axes[:, 0]
    axes[0].plot(rec.time_s, rec.thrust_N, lw=0.5, color="tab:blue")
    axes[0].set_ylabel("thrust [N]")
    if rows == 2:
        axes[1].plot(rec.time_s, rec.torque_Nmm, lw=0.5, color="tab:orange")
        axes[1].set_ylabel("torque [N·mm]")
    marks = marks if marks is not None else {label: rec.metadata[key] for key, label in PHASE_KEYS
                                             if key in rec.metadata}
    for label, t in marks.items():
        for ax in axes:
            ax.axvline(t, color="0.4", lw=0.8, ls="--")
        axes[0].annotate(label, (t, 1.01), xycoords=("data", "axes fraction"), rotation=25, fontsize=8,
                         va="bottom", ha="left", color="0.3")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    m = rec.metadata
    fig.suptitle(f"{rec.name}: f = {m['feed_mm_s']:g} mm/s, N = {m['spindle_rpm']:g} rpm"
                 + (f", effects: {', '.join(m['effects'])}" if m.get("effects") else ""), fontsize=10)
    save(fig, path)
