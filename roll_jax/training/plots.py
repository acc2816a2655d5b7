"""Figures of training runs: the median over seeds with its 25-75% band (the paper's Fig. 4
style), shared by a run's learning curve and the reproduction grid's figures."""

from __future__ import annotations

import numpy as np


def seed_quantiles(rows: list[dict], key: str = "final_distance"):
    """Per env step over seeds: (steps, median, 25th, 75th percentile) as numpy arrays."""
    steps = sorted({r["env_steps"] for r in rows})
    vals = [[r[key] for r in rows if r["env_steps"] == s] for s in steps]
    return (np.asarray(steps), np.asarray([np.median(v) for v in vals]),
            np.asarray([np.percentile(v, 25) for v in vals]),
            np.asarray([np.percentile(v, 75) for v in vals]))


def plot_median_band(ax, rows: list[dict], label: str, key: str = "final_distance", **kw) -> None:
    """Median over seeds with the 25-75% band (the paper's Fig. 4 style) on `ax`."""
    steps, med, lo, hi = seed_quantiles(rows, key)
    if len(steps) <= 20:  # few evaluations: mark them; a single one shows its band as a bar
        kw = {"marker": "o", "markersize": 3, **kw}
    (line,) = ax.plot(steps, med, label=label, **kw)
    ax.fill_between(steps, lo, hi, alpha=0.25, color=line.get_color())
    if len(steps) == 1:
        ax.errorbar(steps, med, yerr=[med - lo, hi - med], color=line.get_color(), capsize=3)
    ax.set_xlabel("env steps")
    ax.set_ylabel(key.replace("_", " "))


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def learning_curve(rows: list[dict], path: str, title: str) -> None:
    """The run's plot: median over seeds with the 25-75% band (the paper's Fig. 4 style)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.5, 3.2))
    plot_median_band(ax, rows, "median over seeds (band 25-75%)")
    if rows and "start_distance" in rows[0]:  # the (fixed) test goals' distance at step 0
        ax.axhline(float(np.median([r["start_distance"] for r in rows])), color="grey",
                   ls="--", lw=1, label="test goals at their start")
    ax.set_title(title)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def compare_curves(runs: list[tuple[str, list[dict]]], path: str, title: str) -> None:
    """Runs' learning curves on one plot: each run's median over seeds with its 25-75% band
    (`roll-compare --plot`), the test goals' distance at their start dashed."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 3.4))
    for label, rows in runs:
        plot_median_band(ax, rows, label)
    starts = [r["start_distance"] for _, rows in runs for r in rows if "start_distance" in r]
    if starts:
        ax.axhline(float(np.median(starts)), color="grey", ls="--", lw=1,
                   label="test goals at their start")
    ax.set_title(title)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def policy_panel(evaluations: list[dict], labels: list[str], goals: list[int], path: str) -> None:
    """The paper's policy visualisation: per goal (a row), the goal image, then each
    evaluation's final frame (seed 0) with its final distance. `evaluations`: dicts with
    "goal_images" [G, H, W, 3], "final_frames" [G, H, W, 3], "final_distance" [G] (or None);
    all evaluated on the same goal images (`roll_jax.analysis.evaluate` with the same --seed)."""
    plt = pyplot()
    cols = 1 + len(evaluations)
    fig, axes = plt.subplots(len(goals), cols, figsize=(1.6 * cols, 1.6 * len(goals)),
                             squeeze=False)
    for r, g in enumerate(goals):
        panels = [(evaluations[0]["goal_images"][g], "goal")]
        for ev, label in zip(evaluations, labels):
            d = ev["final_distance"]
            panels.append((ev["final_frames"][g],
                           label if d is None else f"{label}: {d[g] * 100:.1f} cm"))
        for c, (img, text) in enumerate(panels):
            axes[r, c].imshow(img, interpolation="nearest")
            axes[r, c].set_xticks([])
            axes[r, c].set_yticks([])
            axes[r, c].set_title(text, fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
