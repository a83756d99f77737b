"""Plots of a Monte Carlo run: the TCP error cloud and its projection densities.

An edge module (matplotlib, Agg backend): draws a :class:`~tcr_accuracy.analysis.montecarlo.
MonteCarloResult` like the seed's Fig. 6 and Fig. 12, in mm, as PNG images the caller writes
(:class:`~tcr_accuracy.view.plots_common.PlotFile`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..analysis.montecarlo import MonteCarloResult
from .plots_common import PlotFile, figure, pyplot, save_figure

_PROJECTIONS = (("xy", 0, 1), ("xz", 0, 2), ("yz", 1, 2))


def plot_cloud_3d(result: MonteCarloResult, path, title: str = "", max_points: int = 5000) -> PlotFile:
    """3-D scatter of the TCP position errors [mm] (at most max_points of the kept cloud).

    Equal scales on the three axes (an ellipsoid looks like one), reaching the 99.9 %
    quantile of the largest coordinate so the bulk of the cloud fills the box (the few
    points beyond are not drawn, and the title says how many); at most five ticks per axis;
    the image cropped to the drawing."""
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    cloud = result.cloud[:max_points] * 1e3
    half = float(np.quantile(np.abs(cloud).max(axis=1), 0.999)) if len(cloud) else 1.0
    beyond = int(np.sum(np.abs(cloud).max(axis=1) > half))
    fig = plt.figure(figsize=(5.6, 4.8))
    ax = fig.add_axes((-0.07, -0.02, 0.92, 0.96), projection="3d")
    colour = np.linalg.norm(cloud, axis=1)
    points = ax.scatter(cloud[:, 0], cloud[:, 1], cloud[:, 2], c=colour, s=2, cmap="viridis", axlim_clip=True)
    cax = fig.add_axes((0.84, 0.2, 0.025, 0.6))
    fig.colorbar(points, cax=cax, label="|dP| [mm]")
    ax.set_xlabel("dx [mm]")
    ax.set_ylabel("dy [mm]")
    ax.set_zlabel("dz [mm]")
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(nbins=4, symmetric=True))
    ax.set(xlim=(-half, half), ylim=(-half, half), zlim=(-half, half))
    ax.set_box_aspect((1, 1, 1), zoom=0.95)
    shown = f"{len(cloud)} of {result.n_samples} samples" + (f", {beyond} beyond the box not drawn" if beyond else "")
    fig.suptitle(f"{title}\n({shown})" if title else f"TCP position error, {shown}", y=0.98, fontsize=11)
    return save_figure(fig, path)


def _heat_map_range(values_x, values_y, max_ratio: float = 3.0):
    """((x0, x1), (y0, y1)) [mm] of a projection's heat map: the data's range, each side
    widened to at least 1/max_ratio of the other, so a heat map drawn to scale is never a
    sliver and every axis box is filled by the map."""
    lo = np.array([values_x.min(), values_y.min()])
    hi = np.array([values_x.max(), values_y.max()])
    span = np.maximum(hi - lo, 1e-12)
    wanted = np.maximum(span, span.max() / max_ratio)
    centre = 0.5 * (lo + hi)
    return tuple((float(c - w / 2), float(c + w / 2)) for c, w in zip(centre, wanted))


def plot_projection_densities(result: MonteCarloResult, path, title: str = "", bins: int = 60) -> PlotFile:
    """Three panels: the density of the position errors projected on the xy, xz and yz planes.

    Each heat map fills its axes and is drawn to scale (1 mm is as long on both axes), so an
    elongated cloud shows as one; a side shorter than a third of the other is widened to a
    third."""
    cloud = result.cloud * 1e3
    ranges = {name: _heat_map_range(cloud[:, i], cloud[:, j]) for name, i, j in _PROJECTIONS}
    widths = [(r[0][1] - r[0][0]) / (r[1][1] - r[1][0]) for r in ranges.values()]
    height = 3.4  # [in] of each map; the figure is as wide as the maps and their colour bars need
    fig, axes = figure(1, 3, size=(height * sum(widths) + 3 * 1.5, height + 1.2), width_ratios=widths)
    for ax, (name, i, j) in zip(axes[0], _PROJECTIONS):
        counts, xe, ye, image = ax.hist2d(cloud[:, i], cloud[:, j], bins=bins, range=ranges[name], density=True,
                                          cmap="viridis")
        fig.colorbar(image, ax=ax, label="density [1/mm^2]", fraction=0.08, pad=0.03)
        ax.set_xlabel(f"d{name[0]} [mm]")
        ax.set_ylabel(f"d{name[1]} [mm]")
        ax.set_title(f"{name[0]}-{name[1]} plane")
        ax.set_aspect("equal", adjustable="box")
    fig.suptitle(title or f"Projection densities of the TCP position error ({len(cloud)} samples)")
    return save_figure(fig, path)


def write_montecarlo_plots(result: MonteCarloResult, folder, label: str = "") -> list[PlotFile]:
    """cloud_3d.png and projection_density.png for ``folder`` (nothing is written)."""
    folder = Path(folder)
    prefix = f"{label} " if label else ""
    return [
        plot_cloud_3d(result, folder / "cloud_3d.png", title=f"{prefix}TCP position error cloud"),
        plot_projection_densities(result, folder / "projection_density.png",
                                  title=f"{prefix}projection densities of the TCP position error"),
    ]
