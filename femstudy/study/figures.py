"""Figures of a study run: loads, deflection and von Mises against time, dynamic vs static."""

from __future__ import annotations

from pathlib import Path

from femstudy.plotting import pyplot, save
from femstudy.study.results import LoadingResult

STYLE = {"dynamic": {"color": "tab:orange", "label": "dynamic (cutting + chip evacuation)"},
         "static": {"color": "tab:blue", "label": "static Allotta"}}


def _values(result: LoadingResult, quantity: str):
    """A loading's series of a load (thrust_N, torque_Nmm) or response quantity."""
    return getattr(result, quantity) if quantity in ("thrust_N", "torque_Nmm") else result.series[quantity]


def _panel(ax, results, quantity, ylabel, linestyle="-", suffix=""):
    for r in results:
        style = STYLE[r.name]
        ax.plot(r.time_s, _values(r, quantity), ls=linestyle, marker=".", ms=3, color=style["color"],
                label=style["label"] + suffix)
    ax.set_ylabel(ylabel)
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")


def write_figures(folder: Path, title: str, results: list[LoadingResult]) -> list[str]:
    """Write loads.png, deflection.png and von_mises.png into ``folder``; return their names."""
    plt = pyplot()
    written = []

    fig, (ax_f, ax_t) = plt.subplots(2, 1, figsize=(7.5, 6.5), sharex=True, constrained_layout=True)
    _panel(ax_f, results, "thrust_N", "thrust force [N]")
    _panel(ax_t, results, "torque_Nmm", "torque [N·mm]")
    ax_t.set_xlabel("time after contact [s]")
    fig.suptitle(f"{title}: drilling loads")
    save(fig, folder / "loads.png")
    written.append("loads.png")

    for key, dashed, axis_label, dashed_label, what, name in (
            ("max_deflection_mm", "drill_point_deflection_mm", "deflection [mm]", "at drill point",
             "deflection (displacement magnitude)", "deflection.png"),
            ("max_von_mises_MPa", "max_von_mises_excl_MPa", "von Mises stress [MPa]", "outside the exclusion zone",
             "maximum von Mises stress", "von_mises.png")):
        fig, ax = plt.subplots(figsize=(7.5, 4.5), constrained_layout=True)
        _panel(ax, results, key, axis_label, suffix=", maximum")
        for r in results:
            ax.plot(r.time_s, _values(r, dashed), ls="--", color=STYLE[r.name]["color"],
                    label=f"{STYLE[r.name]['label']}, {dashed_label}")
        ax.legend(fontsize=8, loc="upper left")
        ax.set_xlabel("time after contact [s]")
        ax.set_title(f"{title}: {what}")
        save(fig, folder / name)
        written.append(name)
    return written
