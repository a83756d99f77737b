"""Plots of a Monte Carlo run: the TCP error cloud and its projection densities.

An edge module (matplotlib, Agg backend): draws a :class:`~tcr_accuracy.analysis.montecarlo.
MonteCarloResult` like the seed's Fig. 6 and Fig. 12, in mm, and writes PNG files
atomically (through :func:`~tcr_accuracy.view.plots_common.save_figure`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..analysis.montecarlo import MonteCarloResult
from .plots_common import pyplot, save_figure

_PROJECTIONS = (("xy", 0, 1), ("xz", 0, 2), ("yz", 1, 2))


def plot_cloud_3d(result: MonteCarloResult, path, title: str = "", max_points: int = 5000) -> Path:
    """3-D scatter of the TCP position errors [mm] (at most max_points of the kept cloud)."""
    plt = pyplot()
    cloud = result.cloud[:max_points] * 1e3
    fig = plt.figure(figsize=(6.4, 5.6))
    ax = fig.add_subplot(projection="3d")
    colour = np.linalg.norm(cloud, axis=1)
    points = ax.scatter(cloud[:, 0], cloud[:, 1], cloud[:, 2], c=colour, s=2, cmap="viridis")
    fig.colorbar(points, ax=ax, shrink=0.7, label="|dP| [mm]")
    ax.set_xlabel("dx [mm]")
    ax.set_ylabel("dy [mm]")
    ax.set_zlabel("dz [mm]")
    ax.set_box_aspect(None, zoom=0.85)  # keeps the z label inside the figure
    ax.set_title(title or f"TCP position error, {len(cloud)} of {result.n_samples} samples")
    return save_figure(fig, path)


def plot_projection_densities(result: MonteCarloResult, path, title: str = "", bins: int = 60) -> Path:
    """Three panels: the density of the position errors projected on the xy, xz and yz planes."""
    plt = pyplot()
    cloud = result.cloud * 1e3
    fig, axes = plt.subplots(1, 3, figsize=(14.0, 4.4))
    for ax, (name, i, j) in zip(axes, _PROJECTIONS):
        counts, xe, ye, image = ax.hist2d(cloud[:, i], cloud[:, j], bins=bins, density=True, cmap="jet")
        fig.colorbar(image, ax=ax, label="density [1/mm^2]")
        ax.set_xlabel(f"d{name[0]} [mm]")
        ax.set_ylabel(f"d{name[1]} [mm]")
        ax.set_title(f"{name[0]}-{name[1]} plane")
        ax.set_aspect("equal", adjustable="datalim")
    fig.suptitle(title or f"Projection densities of the TCP position error ({len(cloud)} samples)")
    fig.tight_layout()
    return save_figure(fig, path)


def write_montecarlo_plots(result: MonteCarloResult, folder, label: str = "") -> list[str]:
    """cloud_3d.png and projection_density.png in folder; returns the paths."""
    folder = Path(folder)
    prefix = f"{label} " if label else ""
    return [
        str(plot_cloud_3d(result, folder / "cloud_3d.png", title=f"{prefix}TCP position error cloud")),
        str(plot_projection_densities(result, folder / "projection_density.png",
                                      title=f"{prefix}projection densities of the TCP position error")),
    ]
