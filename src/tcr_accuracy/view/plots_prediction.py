"""Plots for error prediction (an edge module: matplotlib with the Agg backend).

* :func:`plot_similarity` -- De against Dq and against Dp, one row per scenario (the
  second seed's Figs. 4-7).
* :func:`plot_semivariograms` -- semivariance of the standardised x, y, z error against
  joint distance with the fitted Gaussian model, overall and along each joint (its Fig. 10).
* :func:`plot_predicted_errors` -- the predicted error at each query pose, with its
  +-2 std band, and where the queries were measured the held-out miss (``predict``).
* :func:`plot_compensation` -- the predicted error at the targets before and after
  compensation (``compensate``).

Every figure is written through a temporary file and a rename.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plots_common import pyplot, save_figure
from ..analysis.semivariogram import empirical_semivariogram, fit_gaussian_variogram, per_joint_semivariograms


def _figure(n_rows: int, n_cols: int, size):
    plt = pyplot()
    fig, axes = plt.subplots(n_rows, n_cols, figsize=size, squeeze=False)
    return plt, fig, axes


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
    return save_figure(fig, path, tight=True)


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
    return save_figure(fig, path, tight=True)


def plot_predicted_errors(errors: np.ndarray, path, std: np.ndarray | None = None,
                          measured: np.ndarray | None = None) -> Path:
    """The predicted error per query pose, a histogram of its magnitude and, for measured
    queries, the held-out miss per pose [mm].

    Parameters
    ----------
    errors : array of shape (N, 3)
        Predicted errors [m].
    path : path of the PNG
    std : array of shape (N, 3), optional
        Standard deviation of each component [m]: drawn as a +-2 std band.
    measured : array of shape (N, 3), optional
        Measured errors at the same poses [m]: drawn as markers next to the prediction,
        and their miss (measured - predicted) in a third panel, inside the +-2 std band.
    """
    e = np.asarray(errors, dtype=float).reshape(-1, 3) * 1e3
    sd = None if std is None else np.asarray(std, dtype=float).reshape(-1, 3) * 1e3
    norm = np.linalg.norm(e, axis=1)
    rows = np.arange(len(e)) + 2  # CSV row numbers (row 1 is the header)
    marker = "o" if len(e) <= 200 else None
    plt, fig, axes = _figure(1, 3 if measured is not None else 2, (16 if measured is not None else 11, 3.8))
    ax = axes[0, 0]
    colors = {}
    for k, axis in enumerate("xyz"):
        line = ax.plot(rows, e[:, k], marker=marker, ms=3, lw=0.8, label=f"e{axis}")[0]
        colors[axis] = line.get_color()
        if sd is not None:
            ax.fill_between(rows, e[:, k] - 2 * sd[:, k], e[:, k] + 2 * sd[:, k], color=colors[axis], alpha=0.15,
                            lw=0, label=f"e{axis} +- 2 std")
        if measured is not None:
            ax.plot(rows, np.asarray(measured, dtype=float).reshape(-1, 3)[:, k] * 1e3, "x", ms=4,
                    color=colors[axis], label=f"measured e{axis}")
    ax.plot(rows, norm, marker=marker, ms=3, lw=1.4, color="black", label="|e|")
    ax.set_xlabel("query CSV row")
    ax.set_ylabel("predicted error [mm]")
    ax.legend(fontsize=6, ncol=2 if (sd is not None or measured is not None) else 1)
    ax = axes[0, 1]
    ax.hist(norm, bins=min(40, max(5, len(norm) // 4)), color="tab:orange")
    ax.set_xlabel("predicted |e| [mm]")
    ax.set_ylabel("query poses")
    ax.set_title(f"mean {norm.mean():.4g} mm, max {norm.max():.4g} mm", fontsize=9)
    if measured is not None:
        ax = axes[0, 2]
        miss = np.asarray(measured, dtype=float).reshape(-1, 3) * 1e3 - e
        for k, axis in enumerate("xyz"):
            if sd is not None:
                ax.fill_between(rows, -2 * sd[:, k], 2 * sd[:, k], color=colors[axis], alpha=0.12, lw=0,
                                label=f"+- 2 std ({axis})")
            ax.plot(rows, miss[:, k], marker=marker, ms=3, lw=0.8, color=colors[axis], label=f"miss {axis}")
        miss_norm = np.linalg.norm(miss, axis=1)
        ax.axhline(0.0, color="grey", lw=0.6)
        ax.set_xlabel("query CSV row")
        ax.set_ylabel("measured - predicted error [mm]")
        ax.set_title(f"held-out |miss|: mean {miss_norm.mean():.4g} mm, max {miss_norm.max():.4g} mm", fontsize=9)
        ax.legend(fontsize=6, ncol=2)
    return save_figure(fig, path, tight=True)


def plot_compensation(before: np.ndarray, after: np.ndarray, path) -> Path:
    """before, after (N,) predicted |target - real TCP| [m]; histograms on a log axis [mm]."""
    b, a = np.asarray(before, dtype=float) * 1e3, np.asarray(after, dtype=float) * 1e3
    values = np.concatenate([b, a])
    positive = values[values > 0]
    lo = positive.min() if positive.size else 1e-6
    hi = max(values.max(), lo * 10)
    bins = np.logspace(np.log10(lo) - 0.1, np.log10(hi) + 0.1, 40)
    plt, fig, axes = _figure(1, 1, (8, 3.8))
    ax = axes[0, 0]
    ax.hist(np.maximum(b, bins[0]), bins=bins, alpha=0.7, color="tab:orange",
            label=f"uncompensated: mean {b.mean():.4g} mm, max {b.max():.4g} mm")
    ax.hist(np.maximum(a, bins[0]), bins=bins, alpha=0.7, color="tab:green",
            label=f"compensated: mean {a.mean():.2g} mm, max {a.max():.2g} mm")
    ax.set_xscale("log")
    ax.set_xlabel("predicted |target - real TCP| [mm]")
    ax.set_ylabel("targets")
    ax.legend(fontsize=7)
    return save_figure(fig, path, tight=True)
