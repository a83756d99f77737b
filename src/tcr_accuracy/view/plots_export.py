"""The report-ready figure of an export: what each form of the calibration reaches."""

from __future__ import annotations

import numpy as np

from .as_built_summary import KINDS, accuracy_records
from .plots_common import PlotFile, figure, save_figure


def accuracy_plot(accuracy, path) -> PlotFile:
    """Horizontal bars of each form's mean TCP position error [mm] (the max as a whisker), one bar per
    kind of data (held-out, k-fold held-out, measured poses), as the PNG meant for ``path``."""
    records = accuracy_records(accuracy)
    forms = list(dict.fromkeys(r["form"] for r in records))
    kinds = [(k, label) for k, label in KINDS if any(r["on"] == k for r in records)]
    bars = sum(1 for r in records)
    fig, axes = figure(size=(7.0, 0.22 * bars + 0.35 * len(forms) + 1.4))
    ax = axes[0, 0]
    height = 0.8 / max(len(kinds), 1)
    colours = ("#1f77b4", "#ff7f0e", "#7f7f7f")
    for k, (kind, label) in enumerate(kinds):
        y, mean, top = [], [], []
        for i, form in enumerate(forms):
            r = next((r for r in records if r["form"] == form and r["on"] == kind), None)
            if r is not None:
                y.append(i + (k - (len(kinds) - 1) / 2) * height)
                mean.append(r["mean_mm"])
                top.append(r["max_mm"] - r["mean_mm"])
        ax.barh(y, mean, height=height * 0.9, color=colours[k % len(colours)],
                xerr=[np.zeros(len(top)), top], capsize=2, label=f"{label} (mean, whisker to max)")
    ax.set_yticks(range(len(forms)))
    ax.set_yticklabels(forms, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("TCP position error [mm]")
    ax.set_title("What each form of the calibration reaches", fontsize=9)
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", fontsize=8, ncols=min(len(kinds), 2))
    return save_figure(fig, path)
