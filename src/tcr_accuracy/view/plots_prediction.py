"""Plots for error prediction (an edge module: matplotlib with the Agg backend).

* :func:`plot_similarity` -- De against Dq and against Dp, one row per scenario (the
  second seed's Figs. 4-7).
* :func:`plot_semivariograms` -- semivariance of the standardised x, y, z error against
  joint distance with the fitted Gaussian model, overall and along each joint (its Fig. 10).
* :func:`plot_predicted_errors` -- the predicted error at each query pose, with its
  +-2 std band, and where the queries were measured the held-out miss (``predict``).
* :func:`plot_compensation` -- the predicted error at the targets before and after
  compensation (``compensate``).

Every figure is returned as a :class:`~tcr_accuracy.view.plots_common.PlotFile` (PNG bytes and
the file it is meant for); the caller writes it.
"""

from __future__ import annotations


import numpy as np

from .plots_common import PlotFile, figure, legend_beside, save_figure, whole_numbers
from ..analysis.semivariogram import empirical_semivariogram, fit_gaussian_variogram, per_joint_semivariograms


def plot_similarity(scenarios: dict, path) -> PlotFile:
    """scenarios: label -> (PairDistances, SimilarityResult); writes a PNG to path."""
    fig, axes = figure(len(scenarios), 2, size=(9, 2.8 * len(scenarios)))
    for row, (label, (dist, res)) in enumerate(scenarios.items()):
        for col, (values, name, pcc) in enumerate(((dist.joint, "Dq (standardised joints)", res.pcc_joint),
                                                   (dist.cartesian * 1e3, "Dp [mm]", res.pcc_cartesian))):
            ax = axes[row, col]
            ax.scatter(values, dist.error * 1e3, s=3, alpha=0.4)
            ax.set_xlabel(name)
            ax.set_ylabel("De [mm]")
            ax.set_title(f"{label}: PCC = {pcc:.3f}", fontsize=9)
    return save_figure(fig, path)


def plot_semivariograms(q: np.ndarray, errors: np.ndarray, path, n_bins: int = 20,
                        joint_names=None) -> PlotFile:
    """q (n, n_joints) [SI], errors (n, 3) [m]; 4 panels: overall, then per joint for x, y, z."""
    overall = empirical_semivariogram(q, errors, n_bins=n_bins)
    per_joint = per_joint_semivariograms(q, errors, n_bins=n_bins)
    names = joint_names or [f"q{j + 1}" for j in range(q.shape[1])]
    fig, axes = figure(2, 2, size=(12, 7.5))
    ax = axes[0, 0]
    h = np.linspace(0, overall.lags.max(), 100)
    for k, axis in enumerate("xyz"):
        line = ax.plot(overall.lags, overall.semivariance[:, k], "o", ms=3, label=f"{axis} error")[0]
        model = fit_gaussian_variogram(overall, k)
        ax.plot(h, model(h), "-", color=line.get_color(), lw=1,
                label=f"Gaussian fit:\nnugget {model.nugget:.2f}, sill {model.sill:.2f}, range {model.range_:.2f}")
    ax.set_title("all joints", fontsize=9)
    ax.set_xlabel("joint distance (standardised)")
    ax.set_ylabel("semivariance (standardised error)")
    legend_beside(ax)
    for k, axis in enumerate("xyz"):
        ax = axes[(k + 1) // 2, (k + 1) % 2]
        for j, emp in enumerate(per_joint):
            ax.plot(emp.lags, emp.semivariance[:, k], "o-", ms=2, lw=0.8, label=names[j])
        ax.set_title(f"{axis} error along each joint", fontsize=9)
        ax.set_xlabel("distance along the joint (standardised)")
        ax.set_ylabel("semivariance")
        legend_beside(ax)
    return save_figure(fig, path)


def plot_predicted_errors(errors: np.ndarray, path, std: np.ndarray | None = None,
                          measured: np.ndarray | None = None) -> PlotFile:
    """The predicted error per query pose, a histogram of its magnitude and, for measured
    queries, the held-out miss per pose.

    The poses are unrelated to each other, so nothing joins them: each pose is a column of
    markers (ex, ey, ez side by side, |e| in black), readable at 100 poses as at 10.

    Parameters
    ----------
    errors : array of shape (N, 3)
        Predicted errors [m].
    path : path of the PNG
    std : array of shape (N, 3), optional
        Standard deviation of each component [m]: +-2 std error bars (up to 60 poses), and
        the held-out miss in standard deviations.
    measured : array of shape (N, 3), optional
        Measured errors at the same poses [m], in the same sense as ``errors``: crosses next
        to the prediction, and their miss (measured - predicted) in a third panel.
    """
    e = np.asarray(errors, dtype=float).reshape(-1, 3) * 1e3
    sd = None if std is None else np.asarray(std, dtype=float).reshape(-1, 3) * 1e3
    norm = np.linalg.norm(e, axis=1)
    rows = np.arange(len(e)) + 2  # CSV row numbers (row 1 is the header)
    n_panels = 3 if measured is not None else 2
    fig, axes = figure(1, n_panels, size=(5.0 * n_panels, 4.2), width_ratios=[1.6] + [1.0] * (n_panels - 1))
    colors = {axis: f"C{k}" for k, axis in enumerate("xyz")}
    shift = 0.22 if len(e) <= 60 else 0.0  # side by side within a pose's column
    ms = 4 if len(e) <= 60 else 2.5
    ax = axes[0, 0]
    for k, axis in enumerate("xyz"):
        x = rows + (k - 1) * shift
        bars = 2 * sd[:, k] if sd is not None and len(e) <= 60 else None
        ax.errorbar(x, e[:, k], yerr=bars, fmt="o", ms=ms, elinewidth=0.7, color=colors[axis],
                    label=f"e{axis}" + (" +- 2 std" if bars is not None else ""))
        if measured is not None:
            ax.plot(x, np.asarray(measured, dtype=float).reshape(-1, 3)[:, k] * 1e3, "x", ms=ms + 1,
                    color=colors[axis], label=f"measured e{axis}")
    ax.plot(rows, norm, "_", ms=9, mew=2, color="black", label="|e|")
    ax.axhline(0.0, color="grey", lw=0.6)
    ax.set_xlabel("query CSV row")
    ax.set_ylabel("predicted error [mm]")
    ax.set_title("per query pose", fontsize=9)
    handles, labels = ax.get_legend_handles_labels()
    ax = axes[0, 1]
    ax.hist(norm, bins=min(40, max(5, len(norm) // 4)), color="0.45")
    ax.set_xlabel("predicted |e| [mm]")
    ax.set_ylabel("query poses")
    ax.yaxis.set_major_locator(whole_numbers())
    ax.set_title(f"|e|: mean {norm.mean():.4g} mm, max {norm.max():.4g} mm", fontsize=9)
    if measured is not None:
        ax = axes[0, 2]
        miss = np.asarray(measured, dtype=float).reshape(-1, 3) * 1e3 - e
        miss_norm = np.linalg.norm(miss, axis=1)
        scaled = miss / np.maximum(sd, 1e-300) if sd is not None else miss
        for k, axis in enumerate("xyz"):
            ax.plot(rows + (k - 1) * shift, scaled[:, k], "s", ms=ms - 0.5, color=colors[axis], mfc="none")
        if sd is not None:
            for sign in (-2, 2):
                ax.axhline(sign, color="k", ls="--", lw=0.8)
            ax.set_ylabel("(measured - predicted) / std (dashed: +-2)")
        else:
            ax.set_ylabel("measured - predicted error [mm]")
        ax.axhline(0.0, color="grey", lw=0.6)
        ax.set_xlabel("query CSV row")
        ax.set_title(f"held-out |miss|: mean {miss_norm.mean():.4g} mm, max {miss_norm.max():.4g} mm", fontsize=9)
        handles.append(plt_marker("s", "0.3"))
        labels.append("held-out miss (x, y, z in their colours)")
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 5), fontsize=8)
    return save_figure(fig, path)


def plt_marker(marker: str, color) -> object:
    """A legend handle: one hollow marker."""
    from matplotlib.lines import Line2D

    return Line2D([], [], ls="none", marker=marker, color=color, mfc="none")


def plot_compensation(before: np.ndarray, after: np.ndarray, path, heldout_miss: np.ndarray | None = None) -> PlotFile:
    """Histograms on a log axis [mm] of the error at the targets before and after compensation.

    Parameters
    ----------
    before : array of shape (N,)
        Predicted |target - real TCP| with the uncompensated commands [m].
    after : array of shape (N,)
        The model's own predicted miss with the compensated commands [m]: how well the search
        met its own prediction, not what the robot will do.
    heldout_miss : array of shape (M,), optional
        |measured - predicted error| at measured targets [m]: the realistic estimate of what
        compensation leaves. Drawn, and named in the legend, first.
    """
    b, a = np.asarray(before, dtype=float) * 1e3, np.asarray(after, dtype=float) * 1e3
    h = None if heldout_miss is None else np.asarray(heldout_miss, dtype=float) * 1e3
    values = np.concatenate([b, a] + ([h] if h is not None else []))
    positive = values[values > 0]
    lo = positive.min() if positive.size else 1e-6
    hi = max(values.max(), lo * 10)
    bins = np.logspace(np.log10(lo) - 0.1, np.log10(hi) + 0.1, 40)
    fig, axes = figure(1, 1, size=(8.5, 4.2))
    ax = axes[0, 0]
    if h is not None:
        ax.hist(np.maximum(h, bins[0]), bins=bins, alpha=0.8, color="tab:blue",
                label=f"expected after compensation (held-out miss of the prediction at {h.size} measured "
                      f"targets): mean {h.mean():.2g} mm, max {h.max():.2g} mm")
    ax.hist(np.maximum(b, bins[0]), bins=bins, alpha=0.7, color="tab:orange",
            label=f"uncompensated (predicted): mean {b.mean():.4g} mm, max {b.max():.4g} mm")
    ax.hist(np.maximum(a, bins[0]), bins=bins, alpha=0.5, color="0.55", hatch="//",
            label=f"the model's own miss after compensation (not a measurement): mean {a.mean():.2g} mm, "
                  f"max {a.max():.2g} mm")
    ax.set_xscale("log")
    ax.set_xlabel("|target - real TCP| [mm]")
    ax.set_ylabel("targets")
    ax.yaxis.set_major_locator(whole_numbers())
    if h is not None:
        ax.set_title(f"Compensation is expected to leave about {h.mean():.2g} mm (mean held-out miss)", fontsize=10)
    else:
        ax.set_title("Measure some targets for what compensation leaves; the grey bars are the model's own miss",
                     fontsize=10)
    fig.legend(loc="outside lower center", fontsize=8, ncol=1)
    return save_figure(fig, path)
