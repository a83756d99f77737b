"""Plots of sweeps, Sobol indices and trajectory error bands (matplotlib, Agg backend).

An edge module: it draws results computed elsewhere as PNG images the caller writes
(:class:`~tcr_accuracy.view.plots_common.PlotFile`). Lengths in mm, angles in deg.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plots_common import PlotFile, figure, legend_beside, save_figure
from ..analysis.sensitivity import OUTPUTS, SweepResult
from ..analysis.sobol import SobolIndices
from ..analysis.trajectory import TrajectoryErrorBands

_LABELS = {
    "dx": "dx [mm]", "dy": "dy [mm]", "dz": "dz [mm]", "norm": "|dP| [mm]",
    "d_alpha_z": "d alpha (about z) [deg]", "d_beta_y": "d beta (about y) [deg]",
    "d_gamma_x": "d gamma (about x) [deg]", "rotation_angle": "attitude error angle [deg]",
}
POSITION_OUTPUTS = ("dx", "dy", "dz", "norm")
ATTITUDE_OUTPUTS = ("d_alpha_z", "d_beta_y", "d_gamma_x", "rotation_angle")


def _scale(unit_or_output: str) -> float:
    """SI -> display factor (m -> mm, rad -> deg)."""
    if unit_or_output in ("m", "dx", "dy", "dz", "norm"):
        return 1e3
    return 180.0 / np.pi


def plot_sweep(result: SweepResult, outputs, title: str, xlabel: str, path: str | Path) -> PlotFile:
    """One panel per output, one curve per source: TCP error against the swept value."""
    fig, axes = figure(2, 2, size=(12, 7.5))
    xs = result.values * _scale(result.unit)
    for ax, name in zip(axes.ravel(), outputs):
        ys = result.output(name) * _scale(name)
        for i, (source, y) in enumerate(zip(result.source_names, ys)):
            # coinciding curves are common (parallel joint axes): vary markers and dashes
            ax.plot(xs, y, marker="os^vDx*"[i % 7], markersize=4 + (i % 3), linestyle=("-", "--", ":")[i % 3],
                    fillstyle="none", label=source)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(_LABELS[name])
        ax.grid(True, alpha=0.3)
    for ax in axes[:, 1]:
        legend_beside(ax)
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_sobol(indices: SobolIndices, path: str | Path, outputs=POSITION_OUTPUTS, top: int = 12) -> PlotFile:
    """Bars of S1 and ST (with confidence intervals) for the most influential inputs."""
    shown = [o for o in outputs if o in indices.outputs]
    fig, axes = figure(len(shown), 1, size=(11, 2.9 * len(shown) + 0.8))
    for ax, name in zip(axes[:, 0], shown):
        k = indices.outputs.index(name)
        order = indices.ranking(name)[:top]
        pos = np.arange(len(order))
        ax.bar(pos - 0.2, indices.first_order[k, order], 0.4, yerr=indices.first_order_conf[k, order],
               label="first order S1", capsize=2)
        ax.bar(pos + 0.2, indices.total_order[k, order], 0.4, yerr=indices.total_order_conf[k, order],
               label="total ST", capsize=2)
        ax.set_xticks(pos)
        ax.set_xticklabels([indices.source_names[i] for i in order], rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(f"Sobol index of {name}")
        ax.set_ylim(-0.05, 1.05)
        ax.grid(True, axis="y", alpha=0.3)
    legend_beside(axes[0, 0])
    fig.suptitle(f"Sobol indices ({int(indices.conf_level * 100)} % intervals, N = {indices.n_base})")
    return save_figure(fig, path)


def plot_trajectory_bands(bands: TrajectoryErrorBands, path: str | Path, title: str = "") -> PlotFile:
    """dx, dy, dz against time: Monte Carlo mean, quantile band, +-2 first-order std."""
    t = bands.trajectory.time
    lo, hi = bands.quantiles
    fig, axes = figure(3, 1, size=(11, 8.5), sharex=True)
    axes = axes[:, 0]
    for c, (ax, name) in enumerate(zip(axes, ("dx", "dy", "dz"))):
        ax.fill_between(t, bands.lower[:, c] * 1e3, bands.upper[:, c] * 1e3, alpha=0.3,
                        label=f"Monte Carlo {lo * 100:g}-{hi * 100:g} % band")
        ax.plot(t, bands.mean[:, c] * 1e3, label="Monte Carlo mean")
        for sign in (1, -1):
            ax.plot(t, (bands.mean[:, c] + sign * 2 * bands.first_order_std[:, c]) * 1e3, "k--", lw=0.8,
                    label="mean +- 2 first-order std" if sign == 1 else None)
        ax.set_ylabel(f"{name} [mm]")
        ax.grid(True, alpha=0.3)
    legend_beside(axes[0])
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title or f"TCP position error along the trajectory ({bands.n_samples} samples)")
    return save_figure(fig, path)


def plot_trajectory_contributions(bands: TrajectoryErrorBands, path: str | Path, title: str = "",
                                  top: int = 6) -> PlotFile:
    """First-order std of dx, dy, dz caused by each of the ``top`` largest sources, against time."""
    t = bands.trajectory.time
    peak = bands.contributions.max(axis=(0, 2))
    shown = [k for k in np.argsort(-peak)[:top] if peak[k] > 0]
    fig, axes = figure(3, 1, size=(11, 8.5), sharex=True)
    axes = axes[:, 0]
    for c, (ax, name) in enumerate(zip(axes, ("dx", "dy", "dz"))):
        for i, k in enumerate(shown):
            ax.plot(t, bands.contributions[:, k, c] * 1e3, linestyle=("-", "--", ":")[i % 3],
                    label=bands.source_names[k])
        ax.set_ylabel(f"std of {name} [mm]")
        ax.grid(True, alpha=0.3)
    legend_beside(axes[0])
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title or "First-order contribution of each error source")
    return save_figure(fig, path)


__all__ = ["plot_sweep", "plot_sobol", "plot_trajectory_bands", "plot_trajectory_contributions", "OUTPUTS",
           "POSITION_OUTPUTS", "ATTITUDE_OUTPUTS"]
