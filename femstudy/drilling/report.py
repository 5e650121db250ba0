"""Summaries, CSV files and figures of load histories (used by ``femstudy loads``)."""

from __future__ import annotations

import csv
import io
import logging
from dataclasses import dataclass

import numpy as np

from femstudy import atomic
from femstudy.drilling import registry
from femstudy.drilling.history import DrillingConditions, LoadHistory, evaluate
from femstudy.plotting import pyplot, save

log = logging.getLogger(__name__)

CSV_COLUMNS = ["model", "time_s", "depth_mm", "thrust_N", "torque_Nmm"]


def key_points(cond: DrillingConditions, models) -> list[dict]:
    """Thrust and torque of each model at contact, full engagement and breakthrough.

    "contact" is evaluated just after touching (1e-9 s), so step models show their level.
    """
    times = cond.phase_times()
    rows = []
    for model in models:
        for phase in ("contact", "full engagement", "breakthrough"):
            t = max(times[phase], 1e-9)
            h = evaluate(model, cond, [t])
            rows.append({"model": model, "phase": phase, "time_s": t, "depth_mm": h.depth_mm[0],
                         "thrust_N": h.thrust_N[0], "torque_Nmm": h.torque_Nmm[0]})
    return rows


def summary_text(cond: DrillingConditions, models) -> str:
    """A short plain-text summary of the operating point and each model's key loads."""
    mu_f, mu_w = cond.friction
    F0, T0 = cond.static_allotta()
    bone = cond.bone
    inside = "inside" if bone.in_calibrated_range(cond.feed_mm_s, cond.spindle_rpm) else "OUTSIDE"
    lines = [
        f"drilling: f = {cond.feed_mm_s:g} mm/s, N = {cond.spindle_rpm:g} rpm, cortex {cond.cortex_mm:g} mm, "
        f"drill D = {cond.drill.diameter_mm:g} mm, point angle {cond.drill.point_angle_deg:g} deg",
        f"  feed per revolution  a    = {cond.feed_per_rev_mm:.4f} mm/rev",
        f"  bone set '{bone.name}' ({bone.source}); power law {inside} its calibrated range",
        f"  friction             mu_f = {mu_f:.4f}   mu_w = {mu_w:.4f}",
        f"  chip-evacuation growth p  = {cond.growth_exponent:.4f} per drill diameter of depth",
        f"  specific energies    u1   = {bone.u1_MPa:g} MPa (cortical), u2 = {bone.u2_MPa:g} MPa (cancellous)",
        f"  static Allotta load  F    = {F0:.2f} N, T = {T0:.2f} N.mm",
        "",
        f"  {'model':<9} {'phase':<16} {'time_s':>7} {'depth_mm':>9} {'thrust_N':>9} {'torque_Nmm':>11}",
    ]
    for r in key_points(cond, models):
        torque = "-" if np.isnan(r["torque_Nmm"]) else f"{r['torque_Nmm']:.2f}"
        lines.append(f"  {r['model']:<9} {r['phase']:<16} {r['time_s']:7.3f} {r['depth_mm']:9.3f} "
                     f"{r['thrust_N']:9.2f} {torque:>11}")
    return "\n".join(lines)


def write_csv(path, histories: list[LoadHistory]) -> None:
    """Write histories in long form (one row per model and time); missing torque is empty."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for h in histories:
        for row in zip(h.time_s, h.depth_mm, h.thrust_N, h.torque_Nmm):
            writer.writerow([h.model] + ["" if np.isnan(v) else f"{v:.6g}" for v in row])
    atomic.write_text(path, buf.getvalue())


def plot(path, cond: DrillingConditions, histories: list[LoadHistory]) -> None:
    """Thrust and torque against time, all models overlaid, phases marked; saved atomically."""
    plt = pyplot()
    fig, (ax_f, ax_t) = plt.subplots(2, 1, figsize=(8, 7.5), sharex=True, constrained_layout=True)
    for h in histories:
        model = registry.get(h.model)
        style = {"label": model.title, "color": model.colour}
        ax_f.plot(h.time_s, h.thrust_N, **style)
        if not np.all(np.isnan(h.torque_Nmm)):
            ax_t.plot(h.time_s, h.torque_Nmm, **style)
    for phase, t in cond.phase_times().items():
        for ax in (ax_f, ax_t):
            ax.axvline(t, color="0.6", lw=0.8, ls="--")
        ax_f.annotate(phase, (t, 1.01), xycoords=("data", "axes fraction"), rotation=30,
                      va="bottom", ha="left", fontsize=8, color="0.3")
    ax_f.set_ylabel("thrust force [N]")
    ax_t.set_ylabel("torque [N·mm]")
    ax_t.set_xlabel("time after contact [s]")
    fig.suptitle(f"Drilling loads: f = {cond.feed_mm_s:g} mm/s, N = {cond.spindle_rpm:g} rpm, "
                 f"{cond.cortex_mm:g} mm cortex, bone set '{cond.bone.name}'")
    for ax in (ax_f, ax_t):
        ax.grid(True, alpha=0.3)
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=8, loc="best", framealpha=0.9)
    save(fig, path)


@dataclass(frozen=True)
class LoadStudy:
    """Every load model for one unicortical hole: the operating point, the key values and the
    histories (:class:`~femstudy.drilling.history.LoadHistory`, one per model)."""

    conditions: DrillingConditions
    histories: list[LoadHistory]
    text: str

    def rows(self) -> list[dict]:
        """One dict per model and time: model, time_s, depth_mm, thrust_N, torque_Nmm."""
        return [{"model": h.model, "time_s": float(t), "depth_mm": float(d), "thrust_N": float(f),
                 "torque_Nmm": float(m)} for h in self.histories
                for t, d, f, m in zip(h.time_s, h.depth_mm, h.thrust_N, h.torque_Nmm)]


def load_models(feed_mm_s: float, spindle_rpm: float, *, bone: str = "bovine", cortex_mm: float = 6.0,
                diameter_mm: float = 2.7, point_angle_deg: float = 90.0, wall_mm: float | None = None,
                u1_MPa: float | None = None, u2_MPa: float | None = None, dt_s: float = 0.01,
                bones_dir=None, csv_path=None, plot_path=None) -> LoadStudy:
    """Evaluate the Allotta, chip-clogging, Chi and Peng models at one operating point.

    Parameters
    ----------
    feed_mm_s, spindle_rpm : float
        Feed f [mm/s] and spindle speed N [rpm].
    bone : str
        Coefficient set: "bovine", "human", a calibrated set's name or a .toml file.
    cortex_mm, diameter_mm, point_angle_deg, wall_mm
        Cortical thickness [mm], drill diameter [mm], point angle [deg], wall contact length [mm].
    u1_MPa, u2_MPa : float, optional
        Specific cutting energies replacing the bone set's [MPa].
    dt_s : float
        Time step of the histories [s].
    csv_path, plot_path : path-like, optional
        Write the histories (CSV_COLUMNS) and a figure.

    Returns
    -------
    LoadStudy

    Examples
    --------
    >>> study = load_models(2.0, 1500.0)
    >>> round(float(study.histories[1].thrust_N.max()), 1)   # clogging, at breakthrough
    80.8
    """
    from dataclasses import replace

    from femstudy.drilling import Drill, load_bone_set, time_grid
    from femstudy.errors import require

    require(plot_path is None or str(plot_path).lower().endswith((".png", ".pdf", ".svg")),
            f"--plot must end in .png, .pdf or .svg, got '{plot_path}'")
    drill = Drill(diameter_mm=diameter_mm, point_angle_deg=point_angle_deg)
    if wall_mm is not None:
        drill = drill.with_(wall_mm=wall_mm)
    bone_set = load_bone_set(bone, bones_dir)
    for name, value in (("u1_MPa", u1_MPa), ("u2_MPa", u2_MPa)):
        if value is not None:
            bone_set = replace(bone_set, **{name: value})
    cond = DrillingConditions(feed_mm_s, spindle_rpm, cortex_mm, bone_set, drill)
    if not bone_set.in_calibrated_range(feed_mm_s, spindle_rpm):
        log.warning("f = %g mm/s, N = %g rpm lies outside the conditions bone set '%s' was calibrated on; its "
                    "power law is extrapolated", feed_mm_s, spindle_rpm, bone_set.name)
    models = registry.names()
    histories = [evaluate(m, cond, time_grid(cond, dt_s)) for m in models]
    if csv_path:
        write_csv(csv_path, histories)
    if plot_path:
        plot(plot_path, cond, histories)
    return LoadStudy(cond, histories, summary_text(cond, models))
