"""Figures of recordings, processed runs and calibration results (saved atomically)."""

from __future__ import annotations

import numpy as np

from femstudy.plotting import pyplot, save

PHASE_KEYS = (("true_contact_s", "contact"), ("true_full_engagement_s", "full engagement"),
              ("true_breakthrough_s", "breakthrough"), ("true_retraction_s", "retraction"))


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


ROLE_STYLE = {"calibration": dict(color="0.55", lw=0.8, alpha=0.8),
              "held out": dict(color="tab:blue", lw=1.0),
              "outlier": dict(color="tab:red", lw=1.0, ls="--"),
              "validation": dict(color="tab:blue", lw=1.0)}


def _legend_handles(roles):
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], **ROLE_STYLE[r], label=f"{r} run") for r in roles]
    return handles + [Line2D([], [], color="k", lw=2, label="model at the condition's μ, median F_o, T_o")]


def plot_condition_fits(path, result) -> None:
    """Per condition: the processed (filtered) runs and the pooled model, thrust and torque against z."""
    from femstudy.recordings.calibration import model_loads

    plt = pyplot()
    conds = result.conditions
    fig, axes = plt.subplots(len(conds), 2, figsize=(10, 2.4 * len(conds) + 1), squeeze=False,
                             constrained_layout=True)
    for (ax_f, ax_t), c in zip(axes, conds):
        members = [r for r in result.runs if r.condition == (c.feed_mm_s, c.spindle_rpm) and r.role != "validation"]
        for r in members:
            ax_f.plot(r.run.z, r.run.thrust_N, **ROLE_STYLE[r.role])
            ax_t.plot(r.run.z, r.run.torque_Nmm, **ROLE_STYLE[r.role])
        zmax = max(r.run.z[-1] for r in members)
        used = [r for r in members if r.name in c.runs_used]
        z = np.linspace(0, zmax, 200)
        F, T = model_loads(z, used[0].run.drill, c.mu_f, c.mu_w,
                           float(np.median([r.fit.initial_force_N[0] for r in used])),
                           float(np.median([r.fit.initial_torque_Nmm[0] for r in used])))
        ax_f.plot(z, F, color="k", lw=2)
        ax_t.plot(z, T, color="k", lw=2)
        ax_f.set_ylabel(f"f = {c.feed_mm_s:g} mm/s\nN = {c.spindle_rpm:g} rpm\nthrust [N]")
        ax_t.set_ylabel("torque [N·mm]")
        ax_f.set_title(f"μ_f = {c.mu_f:.4f}, p = {c.growth_exponent:.3f}", fontsize=9)
        ax_t.set_title(f"μ_w = {c.mu_w:.4f}", fontsize=9)
        for ax in (ax_f, ax_t):
            ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("z = depth past full engagement / D [-]")
    roles = [k for k in ROLE_STYLE if k != "validation" and any(r.role == k for r in result.runs)]
    axes[0, 1].legend(handles=_legend_handles(roles), fontsize=7, loc="upper left")
    fig.suptitle("Processed runs (isolated, de-drifted, low-pass filtered) and the chip-evacuation model at each "
                 "condition's friction")
    save(fig, path)


def plot_power_law(path, result, truth=None) -> None:
    """μ_f and μ_w per run and per condition with the fitted power law (and the truth, if known)."""
    from femstudy.drilling.friction import evaluate_power_law

    plt = pyplot()
    conds = [(c.feed_mm_s, c.spindle_rpm) for c in result.conditions]
    extra = sorted({r.condition for r in result.by_role("validation")} - set(conds))
    labels = conds + extra
    x_of = {c: k for k, c in enumerate(labels)}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), constrained_layout=True)
    for ax, attr, coef, tcoef, name in ((axes[0], "mu_f", result.bone.a, truth.a if truth else None, "μ_f (flute)"),
                                        (axes[1], "mu_w", result.bone.b, truth.b if truth else None, "μ_w (wall)")):
        for r in result.runs:
            jitter = (hash(r.name) % 100 - 50) / 400
            style = {"outlier": ("x", "tab:red"), "validation": ("o", "tab:blue"),
                     "held out": ("o", "tab:blue")}.get(r.role, ("o", "0.5"))
            ax.plot(x_of[r.condition] + jitter, getattr(r.fit, attr), style[0], color=style[1], ms=4, alpha=0.8)
        ax.errorbar(range(len(conds)), [getattr(c, attr) for c in result.conditions],
                    yerr=[getattr(c, attr) * c.se_ln(getattr(c, f"per_run_{attr}")) for c in result.conditions],
                    fmt="s", color="k", ms=7, capsize=4, label="condition (geometric mean ± SE)")
        f, n = np.array([c[0] for c in labels]), np.array([c[1] for c in labels])
        ax.plot(range(len(labels)), evaluate_power_law(coef, f, n), "_", color="tab:orange", ms=22, mew=3,
                label="fitted power law (Eq 4.5)")
        if tcoef is not None:
            ax.plot(range(len(labels)), evaluate_power_law(tcoef, f, n), "o", mfc="none", color="tab:green",
                    ms=11, mew=2, label="generating law (truth)")
        ax.set_xticks(range(len(labels)), [f"{c[0]:g} mm/s\n{c[1]:g} rpm" + ("\n(valid.)" if c in extra else "")
                                           for c in labels], fontsize=8)
        ax.set_ylabel(f"{name} [-]")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].plot([], [], "o", color="0.5", label="per run (calibration)")
    axes[0].plot([], [], "o", color="tab:blue", label="per run (held out / validation)")
    axes[0].plot([], [], "x", color="tab:red", label="per run (outlier)")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Friction per run, per condition and the power law of bone set '{result.bone.name}'")
    save(fig, path)


def plot_validation(path, result, max_runs: int = 8) -> None:
    """Held-out runs against the power-law model (and the network)."""
    from femstudy.recordings import ann as ann_module
    from femstudy.recordings.calibration import model_loads

    plt = pyplot()
    held = result.by_role("held out", "validation")[:max_runs]
    fig, axes = plt.subplots(len(held), 2, figsize=(10, 2.2 * len(held) + 1), squeeze=False,
                             constrained_layout=True)
    for (ax_f, ax_t), r in zip(axes, held):
        v = r.validation
        F, T = model_loads(r.run.z, r.run.drill, v.mu_f, v.mu_w, v.initial_force_N, v.initial_torque_Nmm)
        ax_f.plot(r.run.z, r.run.thrust_N, color="0.5", lw=1, label="processed run")
        ax_t.plot(r.run.z, r.run.torque_Nmm, color="0.5", lw=1)
        ax_f.plot(r.run.z, F, color="k", lw=1.8, label="power-law model")
        ax_t.plot(r.run.z, T, color="k", lw=1.8)
        if result.ann is not None:
            P = result.ann.best.predict(ann_module.run_inputs(r.run)[0])
            ax_f.plot(r.run.z, P[:, 0], color="tab:purple", lw=1.2, ls="--", label="neural network")
            ax_t.plot(r.run.z, P[:, 1], color="tab:purple", lw=1.2, ls="--")
        ax_f.set_ylabel(f"{r.name[:22]}\nthrust [N]", fontsize=8)
        ax_t.set_ylabel("torque [N·mm]")
        ax_f.set_title(f"f = {v.feed_mm_s:g} mm/s, N = {v.spindle_rpm:g} rpm: R² = {v.r2_thrust:.3f}", fontsize=9)
        ax_t.set_title(f"R² = {v.r2_torque:.3f}", fontsize=9)
        for ax in (ax_f, ax_t):
            ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("z = depth past full engagement / D [-]")
    fig.suptitle("Validation on held-out runs (Table 5-4): model from the power law, F_o and T_o from each run")
    save(fig, path)


def plot_normality(path, results: dict) -> None:
    """Median-rank normal probability plots (Figs 4-13/4-14) with the fitted straight line."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(results), figsize=(5.2 * len(results), 4.6), squeeze=False,
                             constrained_layout=True)
    for ax, (label, res) in zip(axes[0], results.items()):
        pp = res.plot
        ax.plot(pp.values, pp.quantiles, "o", ms=4, color="tab:blue", label="median ranks (i - 0.3)/(n + 0.4)")
        x = np.array([pp.values[0], pp.values[-1]])
        ax.plot(x, (x - pp.intercept) / pp.slope, color="k", lw=1, label=f"straight line, r = {pp.r:.4f}")
        ticks = np.array([0.01, 0.05, 0.2, 0.5, 0.8, 0.95, 0.99])
        from scipy import stats

        ax.set_yticks(stats.norm.ppf(ticks), [f"{100 * t:g} %" for t in ticks])
        ax.set_ylabel("cumulative probability (normal scale)")
        ax.set_xlabel(res.name)
        chi = (f"chi-square {res.chi_square.statistic:.2f} (crit. {res.chi_square.critical:.1f}), "
               if res.chi_square else "")
        ax.set_title(f"n = {res.n}: {chi}Shapiro-Wilk p = {res.shapiro_p:.3f}", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    fig.suptitle("Normal probability plots (median ranks)")
    save(fig, path)


def plot_neuron_study(path, study) -> None:
    """Training and held-out MSE against hidden neurons (Figs 5-12/5-13)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.2), constrained_layout=True)
    ax.semilogy(study.neurons, study.training_mse, "o-", label="training MSE")
    ax.semilogy(study.neurons, study.validation_mse, "s-", label="held-out runs MSE")
    ax.set_xticks(study.neurons)
    ax.set_xlabel("hidden-layer neurons")
    ax.set_ylabel("mean squared error (outputs scaled to [-1, 1])")
    ax.set_title(f"Neural network neuron study: best {study.best.hidden} neuron(s)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    save(fig, path)
