"""Plots of a diagnosis (matplotlib, Agg backend): PNG files for the report.

Edge layer: reads a :class:`~tcr_accuracy.diagnosis.diagnose.Diagnosis`, draws images; each
plot is returned as a :class:`~tcr_accuracy.view.plots_common.PlotFile` for the caller to write.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plots_common import PlotFile, figure, legend_beside, pyplot, save_figure, shared_legend


def _binned_means(values, residual, n_bins=8):
    edges = np.unique(np.quantile(values, np.linspace(0, 1, n_bins + 1)))
    if edges.size < 2:
        return np.array([]), np.zeros((0, 3))
    which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, edges.size - 2)
    centres, means = [], []
    for b in range(edges.size - 1):
        sel = which == b
        if sel.any():
            centres.append(values[sel].mean())
            means.append(residual[sel].mean(axis=0))
    return np.array(centres), np.array(means)


def plot_steps(diagnosis, path: Path) -> PlotFile:
    """The ladder as horizontal bars, one step per row from the top: the effect names read
    level however many steps there are (a real robot's ladder has seven or more)."""
    return plot_ladder([s.effect for s in diagnosis.steps], [s.heldout.rms * 1e3 for s in diagnosis.steps],
                       [s.heldout.mean * 1e3 for s in diagnosis.steps], diagnosis.noise_floor * 1e3, path)


def plot_ladder(effects, rms_mm, mean_mm, noise_floor_mm, path: Path, limit_mm: float | None = None,
                title: str = "How far the gap shrinks (k-fold held-out)") -> PlotFile:
    """The ladder of a diagnosis: held-out RMS and mean [mm] after each step (``effects``, the
    first being frames), on a log axis, with the noise floor and, when given, a limit [mm]."""
    labels = [e if i == 0 else f"+{e}" for i, e in enumerate(effects)]
    fig, axes = figure(1, 1, size=(8, 1.4 + 0.42 * len(labels)))
    ax = axes[0, 0]
    y = np.arange(len(labels))
    ax.barh(y - 0.2, rms_mm, 0.4, label="held-out RMS")
    ax.barh(y + 0.2, mean_mm, 0.4, label="held-out mean")
    ax.axvline(noise_floor_mm, color="k", ls="--", lw=1, label="noise floor")
    if limit_mm is not None:
        ax.axvline(limit_mm, color="C3", ls="-", lw=1.2, label=f"limit {limit_mm:g} mm")
    ax.set_yticks(y, labels)
    ax.invert_yaxis()  # the ladder reads from the top
    ax.set_xlabel("TCP position error [mm]")
    ax.set_xscale("log")
    ax.set_title(title)
    legend_beside(ax)
    return save_figure(fig, path)


def plot_axes(diagnosis, path: Path) -> PlotFile:
    """Histograms per axis: the residual after frames (top row) and the final held-out one
    (bottom row), each on its own scale: the final residual is often a hundred times
    narrower, and on a shared axis it would be a sliver."""
    plt = pyplot()
    fig, axes = figure(2, 3, size=(9.5, 5.6))
    rows = (("after fitting the tracker frame (frames)", diagnosis.gap_residual, "C0"),
            ("final model, held-out", diagnosis.heldout_residual, "C1"))
    per_axis_noise = diagnosis.noise_floor / np.sqrt(3.0) * 1e3
    for r, (label, residual, color) in enumerate(rows):
        for c in range(3):
            ax = axes[r][c]
            values = residual[:, c] * 1e3
            ax.hist(values, bins=30, color=color, alpha=0.8)
            ax.set_xlabel(f"{'xyz'[c]} error [mm]")
            ax.tick_params(labelsize=8)
            if r == 1:  # the noise per axis, for scale: +-1 std
                for sign in (-1, 1):
                    ax.axvline(sign * per_axis_noise, color="k", ls="--", lw=0.8)
        axes[r][0].set_ylabel("measurements")
        axes[r][1].set_title(f"{label}: RMS {np.sqrt(np.mean(np.sum(residual ** 2, axis=1))) * 1e3:.4g} mm",
                             fontsize=9)
    shared_legend(fig, axes, [plt.Line2D([], [], color="k", ls="--", lw=0.8)],
                  [f"+-noise per axis, {per_axis_noise:.3g} mm"])
    fig.suptitle("Residual per axis (each row on its own scale)")
    return save_figure(fig, path)


def _versus(diagnosis, values, names, units, path: Path, title: str) -> PlotFile:
    n = values.shape[1]
    cols = min(3, n)
    rows = int(np.ceil(n / cols))
    fig, axes = figure(rows, cols, size=(3.4 * cols, 2.7 * rows + 0.6))
    residual = diagnosis.gap_residual * 1e3
    for j in range(rows * cols):
        ax = axes[j // cols][j % cols]
        if j >= n:
            ax.axis("off")
            continue
        v = values[:, j]
        ax.scatter(v, np.linalg.norm(residual, axis=1), s=3, c="0.7", label="|e| of each measurement")
        centres, means = _binned_means(v, residual)
        for c in range(3):
            if centres.size:
                ax.plot(centres, means[:, c], marker="o", ms=3, label=f"binned mean of e{'xyz'[c]}")
        ax.set_xlabel(f"{names[j]} [{units[j]}]")
        ax.tick_params(labelsize=8)
    for r in range(rows):
        axes[r][0].set_ylabel("error [mm]")
    shared_legend(fig, axes, *axes[0][0].get_legend_handles_labels())
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_joints(diagnosis, robot, path: Path) -> PlotFile:
    values = diagnosis.q * robot.display_scale
    return _versus(diagnosis, values, robot.joint_names, robot.display_units, path,
                   "Residual after frames against each joint (|e| grey, binned mean per axis)")


def joints_with_gravity_torque(torque, rel_tol: float = 1e-6) -> np.ndarray:
    """Indices of the joints whose gravity torque is more than rounding noise.

    Parameters
    ----------
    torque : array-like of shape (n_measurements, n_joints)
        Gravity torque (N m) or force (N) of each joint at each measurement.
    rel_tol : float
        A joint whose largest |torque| stays below ``rel_tol`` times the largest of any
        joint carries none (a vertical first axis, a wrist turning about the vertical):
        a panel of it would bin numerical noise.
    """
    peak = np.max(np.abs(np.asarray(torque, dtype=float)), axis=0)
    if peak.size == 0 or not np.max(peak) > 0:
        return np.zeros(0, dtype=int)
    return np.flatnonzero(peak > rel_tol * np.max(peak))


def plot_gravity(diagnosis, robot, path: Path) -> PlotFile:
    units = ["Nm" if k == "revolute" else "N" for k in robot.joint_kinds]
    keep = joints_with_gravity_torque(diagnosis.gravity_torque)
    left_out = [n for j, n in enumerate(robot.joint_names) if j not in set(keep.tolist())]
    title = "Residual after frames against gravity torque"
    if left_out:
        title += f" (no gravity torque on {', '.join(left_out)}: not shown)"
    if keep.size == 0:  # no joint carries any: one note instead of panels of noise
        fig, axes = figure(1, 1, size=(6, 1.2))
        ax = axes[0, 0]
        ax.axis("off")
        ax.text(0.5, 0.5, "No joint carries a gravity torque at these poses.", ha="center", va="center")
        return save_figure(fig, path)
    return _versus(diagnosis, diagnosis.gravity_torque[:, keep], [f"tau_g {robot.joint_names[j]}" for j in keep],
                   [units[j] for j in keep], path, title)


def plot_semivariograms(diagnosis, robot, path: Path) -> PlotFile:
    semis = diagnosis.semivariograms
    n = len(semis)
    cols = min(3, n)
    rows = int(np.ceil(n / cols))
    fig, axes = figure(rows, cols, size=(3.4 * cols, 2.7 * rows + 0.6))
    for j in range(rows * cols):
        ax = axes[j // cols][j % cols]
        if j >= n:
            ax.axis("off")
            continue
        s = semis[j]
        for c in range(3):
            ax.plot(s.lags, s.semivariance[:, c], marker="o", ms=3, label=f"e{'xyz'[c]}")
        ax.axhline(1.0, color="k", lw=0.8, ls=":", label="1: no structure")
        ax.set_xlabel(f"|d {robot.joint_names[j]}| (standardised)")
        ax.tick_params(labelsize=8)
    for r in range(rows):
        axes[r][0].set_ylabel("semivariance (standardised)")
    shared_legend(fig, axes, *axes[0][0].get_legend_handles_labels())
    fig.suptitle("Per-joint semivariograms of the residual after frames (low at small lag = varies along it)")
    return save_figure(fig, path)


def plot_regions(diagnosis, path: Path) -> PlotFile:
    """Workspace octants, radius and height bins, and the context columns that were measured.

    Named categories (octants, joints) are horizontal bars, their names written level at a
    readable size however long they are; the binned curves share one legend beside the panels."""
    where = diagnosis.where_mm
    panels = [("octants", None), ("radius", "radius [m]"), ("height", "height z [m]")]
    panels += [(k, label) for k, label in (("payload_kg", "payload [kg]"), ("temperature_c", "temperature [degC]"))
               if k in where]
    if where.get("approach_direction"):
        panels.append(("approach_direction", None))
    cols = min(3, len(panels))
    rows = int(np.ceil(len(panels) / cols))
    fig, axes = figure(rows, cols, size=(3.6 * cols, 3.0 * rows + 0.6))
    flat = axes.ravel()
    for ax in flat[len(panels):]:
        ax.axis("off")
    handles = None
    for ax, (key, label) in zip(flat, panels):
        ax.tick_params(labelsize=8)
        if key == "octants":
            regions = where["octants"]["regions"]
            names = [r["region"] for r in regions]
            ax.barh(np.arange(len(names)), [r["rms_mm"] for r in regions], color="tab:blue")
            ax.set_yticks(np.arange(len(names)), names, fontsize=9, family="monospace")
            ax.invert_yaxis()
            ax.set_xlabel("RMS |e| [mm]")
            ax.set_title("octants around the median TCP", fontsize=9)
        elif key == "approach_direction":
            info = where["approach_direction"]
            names = list(info)
            ax.barh(np.arange(len(names)), [v["difference_norm_mm"] for v in info.values()], color="tab:blue")
            ax.set_yticks(np.arange(len(names)), names, fontsize=8)
            ax.invert_yaxis()
            ax.set_xlabel("|mean(+) - mean(-)| [mm]")
            ax.set_title("approach direction, per joint", fontsize=9)
        else:
            bins = where[key]["bins"]
            if not bins:
                continue
            centres = [0.5 * (b["low"] + b["high"]) for b in bins]
            means = np.array([b["mean_mm"] for b in bins])
            for c in range(3):
                ax.plot(centres, means[:, c], marker="o", ms=3, label=f"binned mean of e{'xyz'[c]}")
            ax.set_xlabel(label)
            ax.set_ylabel("binned mean error [mm]")
            handles = handles or ax.get_legend_handles_labels()
    if handles:
        shared_legend(fig, axes, *handles)
    fig.suptitle("Residual after frames over the workspace and the context")
    return save_figure(fig, path)


def plot_joint_functions(diagnosis, effect: str, path: Path) -> PlotFile:
    """Each joint's fitted function of its own angle (a cyclic error) over the measured range,
    with its 95 % band, one panel per joint, in microradians against degrees."""
    joints = diagnosis.joint_function_bands[effect]
    n = len(joints)
    cols = 2 if n > 1 else 1
    rows = (n + cols - 1) // cols
    fig, axes = figure(rows, cols, size=(9, 2.3 * rows + 0.9))
    for ax, (joint, band) in zip(axes.ravel(), joints.items()):
        angle = np.degrees(band["angle_rad"])
        value, spread = band["value_rad"] * 1e6, 1.96 * band["std_rad"] * 1e6
        ax.fill_between(angle, value - spread, value + spread, color="tab:blue", alpha=0.25, lw=0,
                        label="95 % band")
        ax.plot(angle, value, color="tab:blue", lw=1, label="fitted")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(joint, fontsize=9)
        ax.set_xlabel("joint angle [deg]", fontsize=8)
        ax.set_ylabel("error [urad]", fontsize=8)
        ax.tick_params(labelsize=8)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    shared_legend(fig, axes, handles, labels)
    fig.suptitle(f"{effect}: each joint's fitted error against its own angle", fontsize=10)
    return save_figure(fig, path)


def write_plots(diagnosis, robot, directory: Path) -> dict:
    """All figures, each for a file in ``directory``; returns {label: PlotFile} (nothing is written)."""
    directory = Path(directory)
    functions = {f"{effect} per joint": plot_joint_functions(diagnosis, effect, directory / f"{effect}_joints.png")
                 for effect in getattr(diagnosis, "joint_function_bands", {})}
    return {**functions,
        "Shrink table": plot_steps(diagnosis, directory / "steps.png"),
        "Residual per axis": plot_axes(diagnosis, directory / "axes.png"),
        "Against joint values": plot_joints(diagnosis, robot, directory / "joints.png"),
        "Against gravity torque": plot_gravity(diagnosis, robot, directory / "gravity.png"),
        "Workspace regions and context": plot_regions(diagnosis, directory / "regions.png"),
        "Per-joint semivariograms": plot_semivariograms(diagnosis, robot, directory / "semivariograms.png"),
    }
