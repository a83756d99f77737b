"""Plots for error prediction (an edge module: matplotlib with the Agg backend).

* :func:`plot_similarity` -- De against Dq and against Dp, one row per scenario (the
  second seed's Figs. 4-7).
* :func:`plot_semivariograms` -- semivariance of the standardised x, y, z error against
  joint distance with the fitted Gaussian model, overall and along each joint (its Fig. 10).

Every figure is written through a temporary file and a rename.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .semivariogram import empirical_semivariogram, fit_gaussian_variogram, per_joint_semivariograms


def _figure(n_rows: int, n_cols: int, size):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(n_rows, n_cols, figsize=size, squeeze=False)
    return plt, fig, axes


def _save(plt, fig, path) -> Path:
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fig.tight_layout()
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)
    return path


def plot_similarity(scenarios: dict, path) -> Path:
    """scenarios: label -> (PairDistances, SimilarityResult); writes a PNG to path."""
    plt, fig, axes = _figure(len(scenarios), 2, (9, 2.8 * len(scenarios)))
    for row, (label, (dist, res)) in enumerate(scenarios.items()):
        for col, (values, name, pcc) in enumerate(((dist.joint, "Dq (standardised joints)", res.pcc_joint),
                                                   (dist.cartesian * 1e3, "Dp [mm]", res.pcc_cartesian))):
            ax = axes[row, col]
            ax.scatter(values, dist.error * 1e3, s=3, alpha=0.4)
            ax.set_xlabel(name)
            ax.set_ylabel("De [mm]")
            ax.set_title(f"{label}: PCC = {pcc:.3f}", fontsize=9)
    return _save(plt, fig, path)


def plot_semivariograms(q: np.ndarray, errors: np.ndarray, path, n_bins: int = 20,
                        joint_names=None) -> Path:
    """q (n, n_joints) [SI], errors (n, 3) [m]; 4 panels: overall, then per joint for x, y, z."""
    overall = empirical_semivariogram(q, errors, n_bins=n_bins)
    per_joint = per_joint_semivariograms(q, errors, n_bins=n_bins)
    names = joint_names or [f"q{j + 1}" for j in range(q.shape[1])]
    plt, fig, axes = _figure(2, 2, (10, 7.5))
    ax = axes[0, 0]
    h = np.linspace(0, overall.lags.max(), 100)
    for k, axis in enumerate("xyz"):
        line = ax.plot(overall.lags, overall.semivariance[:, k], "o", ms=3, label=f"{axis} error")[0]
        model = fit_gaussian_variogram(overall, k)
        ax.plot(h, model(h), "-", color=line.get_color(), lw=1,
                label=f"Gaussian fit: nugget {model.nugget:.2f}, sill {model.sill:.2f}, range {model.range_:.2f}")
    ax.set_title("all joints", fontsize=9)
    ax.set_xlabel("joint distance (standardised)")
    ax.set_ylabel("semivariance (standardised error)")
    ax.legend(fontsize=6)
    for k, axis in enumerate("xyz"):
        ax = axes[(k + 1) // 2, (k + 1) % 2]
        for j, emp in enumerate(per_joint):
            ax.plot(emp.lags, emp.semivariance[:, k], "o-", ms=2, lw=0.8, label=names[j])
        ax.set_title(f"{axis} error along each joint", fontsize=9)
        ax.set_xlabel("distance along the joint (standardised)")
        ax.set_ylabel("semivariance")
        ax.legend(fontsize=6)
    return _save(plt, fig, path)
