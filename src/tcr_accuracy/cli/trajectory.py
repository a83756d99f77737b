"""CLI: ``tcr-accuracy trajectory``, Monte Carlo error bands along a joint trajectory.

The TCP position error along a trajectory (seed Fig. 18) as bands over time, the
first-order contribution of each error source, plots and a 3D view. Heavy imports live
inside the run function so that ``--help`` stays instant.
"""

from __future__ import annotations

from .common import (MAX_COUNT, add_sampler_arguments, check_csv_memory, check_memory, error_sampler, integer,
                     sample_bytes)
from .output import RunOutput, add_output_arguments, progress_bar


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "trajectory", help="Monte Carlo error bands of x, y, z along a joint trajectory",
        description="TCP position error along a joint trajectory (seed Fig. 18): each sample is one "
                    "as-built robot following the whole motion. The trajectory is a CSV file (one "
                    "column per joint named <joint>_deg, <joint>_rad, <joint>_mm or <joint>_m, optional "
                    "t_s) or, without --file, the built-in tool-change motion of the tool-changer "
                    "(stowed pose to the working pose, then the telescopic arm extends).",
    )
    add_sampler_arguments(p)
    add_output_arguments(p, view=True)
    p.add_argument("--file", default=None, metavar="CSV", help="joint trajectory CSV file")
    p.add_argument("--samples", type=integer(low=2, high=MAX_COUNT), default=2000,
                   help="Monte Carlo samples (default 2000)")
    p.add_argument("--steps", type=integer(low=2, high=MAX_COUNT), default=121,
                   help="time steps of the built-in motion (default 121)")
    p.set_defaults(run=_run_trajectory)


def _run_trajectory(args) -> int:
    import numpy as np

    from ..exceptions import InputError
    from .common import robot_from_args
    from ..analysis.trajectory import read_trajectory_csv, tool_change_motion, trajectory_error_bands

    out = RunOutput(args, "TCP error along a trajectory")
    robot = robot_from_args(args)
    if args.file:
        check_csv_memory(args, args.file, "--file", 8.0 * (robot.n_joints + 1))
        traj = read_trajectory_csv(args.file, robot)
    else:
        check_memory(args, f"--steps {args.steps}", args.steps * 8.0 * 64)
        try:
            traj = tool_change_motion(robot, n_steps=args.steps)
        except InputError as exc:
            if exc.parameter != "robot":
                raise
            raise InputError(f"{exc} with --file", parameter="robot", value=exc.value) from None
    # every sample's TCP error at every step is kept for the bands (6 numbers each)
    check_memory(args, f"--samples {args.samples} along {len(traj)} steps",
                 args.samples * (sample_bytes(robot) + 8.0 * 6 * len(traj)))
    sampler, label = error_sampler(robot, args)
    update, close = progress_bar(len(traj), "trajectory", args.quiet)
    try:
        bands = trajectory_error_bands(sampler, traj, args.samples, np.random.default_rng(args.seed),
                                       progress=update)
    finally:
        close()
    payload = {
        "robot": robot.name, "preset": label, "trajectory": traj.source, "n_samples": args.samples,
        "seed": args.seed, "joint_names": robot.joint_names, "quantiles": list(bands.quantiles),
        "time_s": traj.time.tolist(), "joint_values_si": traj.q.tolist(),
        "nominal_position_m": bands.nominal_position.tolist(),
        "mean_m": bands.mean.tolist(), "std_m": bands.std.tolist(),
        "lower_m": bands.lower.tolist(), "upper_m": bands.upper.tolist(),
        "norm_mean_m": bands.norm_mean.tolist(), "norm_upper_m": bands.norm_upper.tolist(),
        "first_order_std_m": bands.first_order_std.tolist(),
        "contributions_std_m": {name: bands.contributions[:, k, :].tolist()
                                for k, name in enumerate(bands.source_names)},
    }
    head = (f"{robot.name}, preset {label}: {traj.source}, {len(traj)} steps over "
            f"{traj.time[-1] - traj.time[0]:g} s, {args.samples} as-built robots, seed {args.seed}")
    hi = bands.quantiles[1]
    out.add_text(head, heading="Setup")
    out.add_table("TCP position error along the trajectory (seed Fig. 18)",
                  ["t", "std dx", "std dy", "std dz", "1st-order std dx", "1st-order std dy", "1st-order std dz",
                   f"|dP| {hi * 100:g} % quantile"], _band_rows(bands), units=["s"] + ["mm"] * 7)
    if bands.source_names:
        out.add_table("Largest first-order contributions (std of each source alone)", ["t", "axis", "sources"],
                      _contribution_rows(bands), units=["s", "", "mm"])
    out.add_plots(lambda folder: _trajectory_plots(folder, bands, label, args.samples),
                  {"trajectory_error_bands.png": "Monte Carlo error bands of dx, dy, dz over time",
                   "trajectory_contributions.png": "First-order contribution of each error source over time"})
    if out.scene_wanted:
        out.set_scene(_trajectory_scene(robot, bands, label), "Robot along the trajectory, TCP path coloured "
                      f"by the {hi * 100:g} % quantile of |dP|")
    return out.finish(payload, lambda: _print_trajectory(head, bands))


def _shown_steps(n_steps: int, most: int = 11):
    import numpy as np

    return np.unique(np.linspace(0, n_steps - 1, min(n_steps, most)).round().astype(int))


def _band_rows(bands) -> list[tuple]:
    """t [s], std of dx, dy, dz, their first-order std and the |dP| quantile [mm] at up to 11 steps."""
    t = bands.trajectory.time
    return [(t[i], *(bands.std[i] * 1e3), *(bands.first_order_std[i] * 1e3), bands.norm_upper[i] * 1e3)
            for i in _shown_steps(len(t))]


def _contribution_rows(bands) -> list[tuple]:
    """(t [s], axis, the three largest sources with their std [mm]) at the start, middle and end."""
    import numpy as np

    t = bands.trajectory.time
    rows = []
    for i in np.unique([0, len(t) // 2, len(t) - 1]):
        for c, axis in enumerate("xyz"):
            top = np.argsort(-bands.contributions[i, :, c])[:3]
            rows.append((t[i], axis, ", ".join(f"{bands.source_names[k]} {bands.contributions[i, k, c] * 1e3:.3f}"
                                              for k in top if bands.contributions[i, k, c] > 0)))
    return rows


def _print_trajectory(head: str, bands) -> None:
    import numpy as np

    hi = bands.quantiles[1]
    print(head)
    print(f"  {'t [s]':>7s} {'std dx':>8s} {'std dy':>8s} {'std dz':>8s} {'(1st order)':>26s} "
          f"{f'|dP| {hi * 100:g} %':>11s}   all [mm]")
    for t, sx, sy, sz, fx, fy, fz, norm in _band_rows(bands):
        print(f"  {t:7.2f} {sx:8.4f} {sy:8.4f} {sz:8.4f}   ({fx:7.4f} {fy:7.4f} {fz:7.4f}) {norm:11.4f}")
    i = int(np.argmax(bands.norm_upper))
    print(f"  largest {hi * 100:g} % quantile of |dP|: {bands.norm_upper[i] * 1e3:.4f} mm at "
          f"t = {bands.trajectory.time[i]:g} s")
    if bands.source_names:
        print("  largest first-order contributions (std [mm] of each source alone):")
        rows = _contribution_rows(bands)
        for k in range(0, len(rows), 3):
            print(f"    t = {rows[k][0]:g} s  " + " | ".join(f"{axis}: {text}" for _, axis, text in rows[k:k + 3]))


def _trajectory_plots(folder, bands, label: str, n_samples: int) -> list:
    from pathlib import Path

    from ..view.plots_sensitivity import plot_trajectory_bands, plot_trajectory_contributions

    folder, source = Path(folder), bands.trajectory.source
    files = [plot_trajectory_bands(bands, folder / "trajectory_error_bands.png",
                                   f"TCP position error along {source}, preset {label}, {n_samples} samples")]
    if bands.source_names:
        files.append(plot_trajectory_contributions(
            bands, folder / "trajectory_contributions.png",
            f"First-order std of each error source along {source}, preset {label}"))
    return files


def _trajectory_scene(robot, bands, label: str):
    """The robot at the start, middle and end of the motion, and the nominal TCP path whose
    markers are coloured by the upper quantile of |dP| at each step."""
    from ..view.viewer import LegendEntry, Scene

    traj = bands.trajectory
    scene = Scene(f"{robot.name}: {traj.source}, preset {label}")
    n = len(traj)
    for name, i in (("start", 0), ("middle", n // 2)):
        if 0 < n - 1 - i:
            scene.add_robot(robot, traj.q[i], f"robot_{name}", color=(0.55, 0.57, 0.62), opacity=0.3,
                            include_base=False)
            scene.legend[-1] = LegendEntry(f"robot at t = {traj.time[i]:g} s ({name}), 30 % opaque",
                                           scene.legend[-1].color)
    scene.add_robot(robot, traj.q[-1], "robot_end")
    scene.legend[-1] = LegendEntry(f"robot at t = {traj.time[-1]:g} s (end)")
    scene.add_trajectory(bands.nominal_position, "tcp_path")
    scene.legend[-1] = LegendEntry("nominal TCP path", scene.legend[-1].color)
    hi = bands.quantiles[1]
    scene.add_point_cloud(bands.nominal_position, bands.norm_upper * 1e3, "tcp_error_band",
                          f"|dP| {hi * 100:g} % quantile [mm] along the path", size_m=0.02)
    scene.add_note(f"{bands.n_samples} as-built robots; the markers sit on the nominal TCP path (true scale)")
    return scene
