"""CLI: ``tcr-accuracy sensitivity``, ``tcr-accuracy tolerance`` and ``tcr-accuracy trajectory``.

Which error matters (one-at-a-time sweeps and Sobol indices), how far the spreads may
grow for a reliability target, and the TCP error along a joint trajectory. Heavy
imports live inside the run functions so that ``--help`` stays instant.
"""

from __future__ import annotations

import math

from .cli import add_robot_arguments, format_joint_values, joint_values_si, seed_value
from .cli_output import RunOutput, add_output_arguments, progress_bar

PRESETS = ("table1", "table2", "clearance")


def _add_common(p, pose: bool = False, plots: bool = True, view: bool = False) -> None:
    add_robot_arguments(p)
    if pose:
        p.add_argument("--q", nargs="+", type=float, metavar="VALUE",
                       help="joint values: revolute [deg], prismatic [mm] (default: the working pose)")
    source = p.add_mutually_exclusive_group()
    source.add_argument("--preset", choices=PRESETS, default=None,
                        help="error distributions: the seed's Table 1, Table 2 or Table 4 (joint clearance); "
                             "default table2")
    source.add_argument("--config", default=None, metavar="FILE",
                        help="TOML or YAML file of error distributions (as for 'montecarlo --config')")
    p.add_argument("--seed", type=seed_value, default=0, help="random seed (default 0)")
    add_output_arguments(p, plots=plots, view=view)


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "sensitivity", help="which error source matters: sweeps and Sobol indices",
        description="One-at-a-time sweeps as in the seed's Fig. 7-9 (each link length error at "
                    "+-0.02/0.04/0.06 mm, each joint angle error at +-0.02..0.1 deg) and Fig. 13-16 "
                    "(joint clearance offsets and deflections of one joint at a time), then "
                    "first-order and total Sobol indices (SALib) of every source of the --preset "
                    "for dx, dy, dz, |dP| and the attitude errors.",
    )
    _add_common(p, pose=True)
    p.add_argument("--sobol-samples", type=int, default=1024, metavar="N",
                   help="SALib base sample size, a power of two (model runs: N x (sources + 2)); default 1024")
    p.set_defaults(run=_run_sensitivity)

    p = sub.add_parser(
        "tolerance", help="largest spreads that still meet a reliability target",
        description="Tolerance allocation: the largest factor on the spreads of the --preset (all "
                    "of them, or only those of --groups) such that P(|dP| < T) >= p at the pose, "
                    "from a fixed-seed Monte Carlo with common random numbers. Prints the "
                    "allowed spreads in mm and deg.",
    )
    _add_common(p, pose=True, plots=False)
    p.add_argument("--target-tol", type=float, default=0.25, metavar="MM",
                   help="position tolerance T on |dP| [mm] (default 0.25)")
    p.add_argument("--target-prob", type=float, default=0.95, metavar="P",
                   help="required probability P(|dP| < T), in (0, 1) (default 0.95)")
    p.add_argument("--groups", default=None, metavar="G1,G2",
                   help="scale only these groups (table1/table2: link_length, drive, axis_deflection; "
                        "clearance: axial, radial, deflection); default all")
    p.add_argument("--per-group", action="store_true",
                   help="also the allowance of each group alone, the others at their spreads")
    p.add_argument("--samples", type=int, default=50_000, help="Monte Carlo samples (default 50000)")
    p.set_defaults(run=_run_tolerance)

    p = sub.add_parser(
        "trajectory", help="Monte Carlo error bands of x, y, z along a joint trajectory",
        description="TCP position error along a joint trajectory (seed Fig. 18): each sample is one "
                    "as-built robot following the whole motion. The trajectory is a CSV file (one "
                    "column per joint named <joint>_deg, <joint>_rad, <joint>_mm or <joint>_m, optional "
                    "t_s) or, without --file, the built-in tool-change motion of the tool-changer "
                    "(stowed pose to the working pose, then the telescopic arm extends).",
    )
    _add_common(p, view=True)
    p.add_argument("--file", default=None, metavar="CSV", help="joint trajectory CSV file")
    p.add_argument("--samples", type=int, default=2000, help="Monte Carlo samples (default 2000)")
    p.add_argument("--steps", type=int, default=121, help="time steps of the built-in motion (default 121)")
    p.set_defaults(run=_run_trajectory)


# ---------------------------------------------------------------------------------------
def _sampler(robot, args):
    """The error sampler of --preset or --config, and a label for reports."""
    from .cli_montecarlo import sampler_from_args

    sampler = sampler_from_args(robot, args.preset, args.config)
    return sampler, args.preset or ("table2" if args.config is None else f"config {args.config}")


def _si_series(result):
    from .sensitivity import OUTPUT_UNITS, OUTPUTS

    return {name: {f"{o}_{u}": result.errors[k, :, i].tolist() for i, (o, u) in enumerate(zip(OUTPUTS, OUTPUT_UNITS))}
            for k, name in enumerate(result.source_names)}


def _sweep_json(result) -> dict:
    return {"values_" + result.unit: result.values.tolist(), "sources": _si_series(result)}


def _run_sensitivity(args) -> int:
    from .exceptions import InputError
    from .robot import load_robot
    from .random_inputs import random_inputs
    from .sensitivity import OUTPUT_UNITS, OUTPUTS, clearance_sweeps, seed_sweeps
    from .sobol import sobol_indices

    n = args.sobol_samples
    if n < 2 or n & (n - 1):
        raise InputError(f"--sobol-samples {n}: must be a power of two >= 2 (e.g. 512, 1024, 4096)")
    out = RunOutput(args, "Sensitivity of the TCP error to each error source")
    robot = load_robot(args.robot, args.tool)
    q = joint_values_si(robot, args.q)
    sampler, label = _sampler(robot, args)
    sweeps = seed_sweeps(robot, q)
    clearance = None
    if any(k == "revolute" for k in robot.joint_kinds):
        from .clearance import ClearanceModel

        clearance = clearance_sweeps(ClearanceModel.from_robot(robot), q)
    n_inputs = len(random_inputs(sampler).sources)
    update, close = progress_bar(n * (n_inputs + 2), "Sobol", args.quiet)
    try:
        indices = sobol_indices(sampler, q, n_base=n, seed=args.seed, progress=update)
    finally:
        close()

    payload = {
        "robot": robot.name, "preset": label, "joint_names": robot.joint_names,
        "joint_values_si": q.tolist(),
        "sweeps": {key: _sweep_json(r) for key, r in sweeps.items()},
        "clearance_sweeps": {key: _sweep_json(r) for key, r in (clearance or {}).items()},
        "sobol": {
            "n_base": indices.n_base, "n_evaluations": indices.n_evaluations,
            "conf_level": indices.conf_level, "seed": args.seed,
            "outputs": {o: {
                "variance_" + OUTPUT_UNITS[OUTPUTS.index(o)] + "2": float(indices.variance[k]),
                "sources": [_index_entry(indices, k, i) for i in indices.ranking(o)],
            } for k, o in enumerate(indices.outputs)},
        },
    }
    shown = _shown_sweeps(sweeps, clearance)
    out.add_text(f"{robot.name}, preset {label}, at {format_joint_values(robot, q)}", heading="Setup")
    for title, result in shown:
        out.add_table(f"One at a time (seed Fig. 7-9): {title}", SWEEP_COLUMNS, _sweep_rows(result, -1),
                      note="TCP error with this source alone at its largest swept value")
    out.add_table(_sobol_title(indices), SOBOL_COLUMNS, _sobol_rows(indices))
    out.add_plots(lambda folder: _sensitivity_plots(folder, sweeps, clearance, indices))
    return out.finish(payload, lambda: _print_sensitivity(robot, q, label, shown, indices))


#: Columns of the one-at-a-time tables (printed and in the report).
SWEEP_COLUMNS = ("source", "dx [mm]", "dy [mm]", "dz [mm]", "|dP| [mm]", "angle [deg]")
#: Columns of the Sobol table.
SOBOL_COLUMNS = ("source", "group", "S1 |dP|", "+-", "ST |dP|", "+-", "ST dx", "ST dy", "ST dz", "linear S1 dx/dy/dz")


def _shown_sweeps(sweeps, clearance) -> list[tuple[str, object]]:
    shown = [("link length +0.06 mm", sweeps["link_length"]), ("joint angle +0.1 deg", sweeps["joint_angle"])]
    if clearance:
        shown += [("clearance rod s = +0.5 mm along u (theta = 0)", clearance["radial_u"]),
                  ("clearance deflection w_y = +0.087 rad", clearance["deflection_v"])]
    return shown


def _sweep_rows(result, column: int) -> list[tuple]:
    """One row per source: dx, dy, dz, |dP| [mm] and the attitude error angle [deg] at one swept value."""
    e = result.errors[:, column]
    return [(name, *(e[k, :4] * 1e3), math.degrees(e[k, 7])) for k, name in enumerate(result.source_names)]


def _sobol_title(indices) -> str:
    return (f"Sobol indices (SALib, N = {indices.n_base}, {indices.n_evaluations} model runs, "
            f"{indices.conf_level * 100:g} % intervals), ranked by total index of |dP|")


def _sobol_rows(indices) -> list[tuple]:
    k = indices.outputs.index("norm")
    kx = [indices.outputs.index(o) for o in ("dx", "dy", "dz")]
    rows = []
    for i in indices.ranking("norm"):
        lin = "/".join("-" if math.isnan(v) else f"{v:.3f}" for v in indices.linear_share[:, i])
        rows.append((indices.source_names[i], indices.groups[i], indices.first_order[k, i],
                     indices.first_order_conf[k, i], indices.total_order[k, i], indices.total_order_conf[k, i],
                     *(indices.total_order[c, i] for c in kx), lin))
    return rows


def _print_sensitivity(robot, q, label, shown, indices) -> None:
    print(f"{robot.name}, preset {label}, at {format_joint_values(robot, q)}")
    print("\nOne at a time (seed Fig. 7-9): TCP error with one source at its largest swept value")
    for title, result in shown:
        w = max(8, *(len(n) for n in result.source_names))
        print(f"  {title}:")
        print(f"    {'source':{w}s} {'dx [mm]':>9s} {'dy [mm]':>9s} {'dz [mm]':>9s} {'|dP| [mm]':>10s} "
              f"{'angle [deg]':>12s}")
        for name, dx, dy, dz, norm, angle in _sweep_rows(result, -1):
            print(f"    {name:{w}s} {dx:9.4f} {dy:9.4f} {dz:9.4f} {norm:10.4f} {angle:12.6f}")
    print(f"\n{_sobol_title(indices)}:")
    w = max(26, *(len(n) for n in indices.source_names))
    print(f"  {'source':{w}s} {'group':16s} {'S1 |dP|':>16s} {'ST |dP|':>16s}   {'ST dx':>6s} {'ST dy':>6s} "
          f"{'ST dz':>6s}   {'linear S1 dx/dy/dz':>20s}")
    for name, group, s1, s1c, st, stc, stx, sty, stz, lin in _sobol_rows(indices):
        print(f"  {name:{w}s} {group:16s} {s1:7.3f} +- {s1c:5.3f} {st:7.3f} +- {stc:5.3f}   "
              f"{stx:6.3f} {sty:6.3f} {stz:6.3f}   {lin:>20s}")


def _index_entry(indices, k: int, i: int) -> dict:
    def num(v):
        return None if math.isnan(v) else float(v)

    entry = {"name": indices.source_names[i], "group": indices.groups[i],
             "S1": num(indices.first_order[k, i]), "S1_conf": num(indices.first_order_conf[k, i]),
             "ST": num(indices.total_order[k, i]), "ST_conf": num(indices.total_order_conf[k, i])}
    output = indices.outputs[k]
    if output in ("dx", "dy", "dz"):
        entry["linear_S1"] = num(indices.linear_share[("dx", "dy", "dz").index(output), i])
    return entry


def _sensitivity_plots(folder, sweeps, clearance, indices) -> list[str]:
    from pathlib import Path

    from .plots_sensitivity import ATTITUDE_OUTPUTS, POSITION_OUTPUTS, plot_sobol, plot_sweep

    d = Path(folder)
    files = [
        plot_sweep(sweeps["link_length"], POSITION_OUTPUTS, "Link length error alone -> TCP position (seed Fig. 7)",
                   "link length error [mm]", d / "sweep_link_length_position.png"),
        plot_sweep(sweeps["joint_angle"], POSITION_OUTPUTS, "Joint angle error alone -> TCP position (seed Fig. 8)",
                   "joint angle error [deg]", d / "sweep_joint_angle_position.png"),
        plot_sweep(sweeps["joint_angle"], ATTITUDE_OUTPUTS, "Joint angle error alone -> TCP attitude (seed Fig. 9)",
                   "joint angle error [deg]", d / "sweep_joint_angle_attitude.png"),
    ]
    if clearance:
        titles = {"axial": "axial movement d", "radial_u": "clearance rod s along u (theta = 0)",
                  "radial_v": "clearance rod s along v (theta = 90 deg)",
                  "deflection_u": "deflection w_x (about u)", "deflection_v": "deflection w_y (about v)"}
        for key, result in clearance.items():
            unit = "mm" if result.unit == "m" else "deg"
            figs = "Fig. 13" if result.unit == "m" else "Fig. 14"
            files.append(plot_sweep(result, POSITION_OUTPUTS, f"Joint clearance {titles[key]} -> TCP position "
                                    f"(seed {figs})", f"{titles[key]} [{unit}]", d / f"sweep_clearance_{key}_position.png"))
            if result.unit == "rad":
                files.append(plot_sweep(result, ATTITUDE_OUTPUTS, f"Joint clearance {titles[key]} -> TCP attitude "
                                        "(seed Fig. 15-16)", f"{titles[key]} [deg]",
                                        d / f"sweep_clearance_{key}_attitude.png"))
    files.append(plot_sobol(indices, d / "sobol_indices.png"))
    return [str(f) for f in files]


# ---------------------------------------------------------------------------------------
def _run_tolerance(args) -> int:
    import numpy as np

    from .exceptions import AnalysisError, InputError
    from .robot import load_robot
    from .random_inputs import random_inputs
    from .tolerance import allocate_tolerance

    if not (args.target_tol > 0 and math.isfinite(args.target_tol)):
        raise InputError(f"--target-tol {args.target_tol}: the tolerance must be a number > 0 [mm]")
    if not (0.0 < args.target_prob < 1.0):
        raise InputError(f"--target-prob {args.target_prob}: the probability must lie strictly between 0 and 1")
    if args.samples < 10:
        raise InputError(f"--samples {args.samples}: need at least 10")
    out = RunOutput(args, "Tolerance allocation")
    robot = load_robot(args.robot, args.tool)
    q = joint_values_si(robot, args.q)
    sampler, label = _sampler(robot, args)
    inputs = random_inputs(sampler)
    known = sorted({g for g, ok in zip(inputs.groups, inputs.scalable) if ok})
    groups = None
    if args.groups:
        groups = [g.strip() for g in args.groups.split(",") if g.strip()]
        unknown = [g for g in groups if g not in known]
        if unknown or not groups:
            raise InputError(f"--groups {args.groups}: unknown group {', '.join(unknown) or '(none given)'} "
                             f"(groups of {label}: {', '.join(known)})")
    tol = args.target_tol * 1e-3
    update, close = progress_bar(None, "tolerance (Monte Carlo runs)", args.quiet)
    try:
        main = allocate_tolerance(sampler, q, tol, args.target_prob, groups=groups, n_samples=args.samples,
                                  rng=np.random.default_rng(args.seed), progress=update)
        per_group = {}
        if args.per_group:
            for g in known:
                try:
                    per_group[g] = allocate_tolerance(sampler, q, tol, args.target_prob, groups=[g],
                                                      n_samples=args.samples, rng=np.random.default_rng(args.seed),
                                                      progress=update)
                except AnalysisError as exc:
                    per_group[g] = str(exc)
    finally:
        close()

    payload = {
        "robot": robot.name, "preset": label, "joint_names": robot.joint_names,
        "joint_values_si": q.tolist(), "tolerance_m": tol, "target_probability": args.target_prob,
        "n_samples": args.samples, "seed": args.seed, **_allocation_json(main),
    }
    if args.per_group:
        payload["per_group"] = {g: (_allocation_json(a) if not isinstance(a, str) else {"error": a})
                                for g, a in per_group.items()}
    head = _tolerance_head(robot, q, label, args, main)
    out.add_text("\n\n".join(head), heading="Setup and result")
    out.add_table("Allowed spreads (standard deviations)", ["source", "group", "std now", "std allowed", "unit"],
                  _spread_rows(main))
    if args.per_group:
        out.add_table("Each group alone (the others at their spreads)", ["group", "largest factor"],
                      [(g, a if isinstance(a, str) else a.factor) for g, a in per_group.items()],
                      float_format="{:.6g}")
    return out.finish(payload, lambda: _print_tolerance(head, main, per_group if args.per_group else None))


def _tolerance_head(robot, q, label, args, main) -> list[str]:
    what = ", ".join(main.scaled_groups) if main.scaled_groups else "all"
    return [f"{robot.name}, preset {label}, at {format_joint_values(robot, q)}",
            f"Target P(|dP| < {args.target_tol:g} mm) >= {args.target_prob:g}; {args.samples} samples, "
            f"seed {args.seed}",
            f"  with the preset's spreads:  P = {main.nominal_probability:.4f}",
            f"  largest factor on the spreads ({what}): {main.factor:.6g}  (P = {main.achieved_probability:.4f})"]


def _spread_rows(allocation) -> list[tuple]:
    """(source, group, std now, std allowed, unit) in mm or deg."""
    rows = []
    for s in allocation.spreads:
        scale, unit = (1e3, "mm") if s.unit == "m" else (180.0 / math.pi, "deg")
        rows.append((s.name, s.group, s.nominal_std * scale, s.allowed_std * scale, unit))
    return rows


def _print_tolerance(head, main, per_group) -> None:
    print("\n".join(head))
    w = max(26, *(len(s.name) for s in main.spreads))
    print(f"  {'source':{w}s} {'group':16s} {'std now':>14s} {'std allowed':>14s}")
    for name, group, now, allowed, unit in _spread_rows(main):
        print(f"  {name:{w}s} {group:16s} {now:10.5g} {unit:3s} {allowed:10.5g} {unit:3s}")
    if per_group is not None:
        print("  each group alone (the others at their spreads):")
        for g, a in per_group.items():
            if isinstance(a, str):
                print(f"    {g:16s} impossible: {a}")
            else:
                print(f"    {g:16s} factor {a.factor:.6g}")


def _allocation_json(a) -> dict:
    spreads = []
    for s in a.spreads:
        u = s.unit
        spreads.append({"name": s.name, "group": s.group, f"nominal_std_{u}": s.nominal_std,
                        f"allowed_std_{u}": s.allowed_std})
    return {"factor": a.factor, "scaled_groups": list(a.scaled_groups) if a.scaled_groups else None,
            "nominal_probability": a.nominal_probability, "achieved_probability": a.achieved_probability,
            "spreads": spreads}


# ---------------------------------------------------------------------------------------
def _run_trajectory(args) -> int:
    import numpy as np

    from .exceptions import InputError
    from .robot import load_robot
    from .trajectory import read_trajectory_csv, tool_change_motion, trajectory_error_bands

    if args.samples < 2:
        raise InputError(f"--samples {args.samples}: need at least 2")
    out = RunOutput(args, "TCP error along a trajectory")
    robot = load_robot(args.robot, args.tool)
    if args.file:
        traj = read_trajectory_csv(args.file, robot)
    else:
        if args.steps < 2:
            raise InputError(f"--steps {args.steps}: need at least 2")
        traj = tool_change_motion(robot, n_steps=args.steps)
    sampler, label = _sampler(robot, args)
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


def _trajectory_plots(folder, bands, label: str, n_samples: int) -> list[str]:
    from pathlib import Path

    from .plots_sensitivity import plot_trajectory_bands, plot_trajectory_contributions

    folder, source = Path(folder), bands.trajectory.source
    files = [plot_trajectory_bands(bands, folder / "trajectory_error_bands.png",
                                   f"TCP position error along {source}, preset {label}, {n_samples} samples")]
    if bands.source_names:
        files.append(plot_trajectory_contributions(
            bands, folder / "trajectory_contributions.png",
            f"First-order std of each error source along {source}, preset {label}"))
    return [str(f) for f in files]


def _trajectory_scene(robot, bands, label: str):
    """The robot at the start, middle and end of the motion, and the nominal TCP path whose
    markers are coloured by the upper quantile of |dP| at each step."""
    from .viewer import LegendEntry, Scene

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
