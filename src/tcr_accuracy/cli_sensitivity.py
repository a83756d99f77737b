"""CLI: ``tcr-accuracy sensitivity``, ``tcr-accuracy tolerance`` and ``tcr-accuracy trajectory``.

Which error matters (one-at-a-time sweeps and Sobol indices), how far the spreads may
grow for a reliability target, and the TCP error along a joint trajectory. Heavy
imports live inside the run functions so that ``--help`` stays instant.
"""

from __future__ import annotations

import math
import sys

from .cli import EXIT_OK, add_robot_arguments, emit_json, format_joint_values, joint_values_si

PRESETS = ("table1", "table2", "clearance")


def _add_common(p, pose: bool = False) -> None:
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
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--json", nargs="?", const="-", default=None, metavar="FILE",
                   help="write JSON (SI units, unit-suffixed keys) to FILE, or to stdout without FILE")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


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
    p.add_argument("--plots", default=None, metavar="DIR", help="write PNG plots of the sweeps and indices to DIR")
    p.set_defaults(run=_run_sensitivity)

    p = sub.add_parser(
        "tolerance", help="largest spreads that still meet a reliability target",
        description="Tolerance allocation: the largest factor on the spreads of the --preset (all "
                    "of them, or only those of --groups) such that P(|dP| < T) >= p at the pose, "
                    "from a fixed-seed Monte Carlo with common random numbers. Prints the "
                    "allowed spreads in mm and deg.",
    )
    _add_common(p, pose=True)
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
    _add_common(p)
    p.add_argument("--file", default=None, metavar="CSV", help="joint trajectory CSV file")
    p.add_argument("--samples", type=int, default=2000, help="Monte Carlo samples (default 2000)")
    p.add_argument("--steps", type=int, default=121, help="time steps of the built-in motion (default 121)")
    p.add_argument("--plots", default=None, metavar="DIR", help="write the error-band plot (PNG) to DIR")
    p.set_defaults(run=_run_trajectory)


# ---------------------------------------------------------------------------------------
def _sampler(robot, args):
    """The error sampler of --preset or --config, and a label for reports."""
    from .cli_montecarlo import sampler_from_args

    sampler = sampler_from_args(robot, args.preset, args.config)
    return sampler, args.preset or ("table2" if args.config is None else f"config {args.config}")


def _progress(total: int | None, desc: str, quiet: bool):
    """A tqdm bar on stderr (off with --quiet or when stderr is not a terminal) as a callback."""
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, file=sys.stderr, leave=False,
               disable=quiet or not sys.stderr.isatty())
    return bar.update, bar.close


def _si_series(result):
    from .sensitivity import OUTPUT_UNITS, OUTPUTS

    return {name: {f"{o}_{u}": result.errors[k, :, i].tolist() for i, (o, u) in enumerate(zip(OUTPUTS, OUTPUT_UNITS))}
            for k, name in enumerate(result.source_names)}


def _sweep_json(result) -> dict:
    return {"values_" + result.unit: result.values.tolist(), "sources": _si_series(result)}


def _run_sensitivity(args) -> int:
    import numpy as np

    from .exceptions import InputError
    from .robot import load_robot
    from .sensitivity import (OUTPUT_UNITS, OUTPUTS, clearance_sweeps, random_inputs, seed_sweeps,
                              sobol_indices)

    n = args.sobol_samples
    if n < 2 or n & (n - 1):
        raise InputError(f"--sobol-samples {n}: must be a power of two >= 2 (e.g. 512, 1024, 4096)")
    robot = load_robot(args.robot, args.tool)
    q = joint_values_si(robot, args.q)
    sampler, label = _sampler(robot, args)
    sweeps = seed_sweeps(robot, q)
    clearance = None
    if any(k == "revolute" for k in robot.joint_kinds):
        from .clearance import ClearanceModel

        clearance = clearance_sweeps(ClearanceModel.from_robot(robot), q)
    n_inputs = len(random_inputs(sampler).sources)
    update, close = _progress(n * (n_inputs + 2), "Sobol", args.quiet)
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
    if args.plots:
        payload["plots"] = _sensitivity_plots(args.plots, sweeps, clearance, indices)
    if args.json is not None:
        emit_json(payload, args.json)
        if args.json == "-":
            return EXIT_OK

    print(f"{robot.name}, preset {label}, at {format_joint_values(robot, q)}")
    print("\nOne at a time (seed Fig. 7-9): TCP error with one source at its largest swept value")
    _print_sweep(sweeps["link_length"], "link length +0.06 mm", -1)
    _print_sweep(sweeps["joint_angle"], "joint angle +0.1 deg", -1)
    if clearance:
        _print_sweep(clearance["radial_u"], "clearance rod s = +0.5 mm along u (theta = 0)", -1)
        _print_sweep(clearance["deflection_v"], "clearance deflection w_y = +0.087 rad", -1)
    print(f"\nSobol indices (SALib, N = {n}, {indices.n_evaluations} model runs, "
          f"{indices.conf_level * 100:g} % intervals), ranked by total index of |dP|:")
    k = indices.outputs.index("norm")
    kx = [indices.outputs.index(o) for o in ("dx", "dy", "dz")]
    w = max(26, *(len(n) for n in indices.source_names))
    print(f"  {'source':{w}s} {'group':16s} {'S1 |dP|':>16s} {'ST |dP|':>16s}   {'ST dx':>6s} {'ST dy':>6s} "
          f"{'ST dz':>6s}   {'linear S1 dx/dy/dz':>20s}")
    for i in indices.ranking("norm"):
        st = " ".join(f"{indices.total_order[c, i]:6.3f}" for c in kx)
        lin = "/".join("   -" if np.isnan(v) else f"{v:.3f}" for v in indices.linear_share[:, i])
        print(f"  {indices.source_names[i]:{w}s} {indices.groups[i]:16s} "
              f"{indices.first_order[k, i]:7.3f} +- {indices.first_order_conf[k, i]:5.3f} "
              f"{indices.total_order[k, i]:7.3f} +- {indices.total_order_conf[k, i]:5.3f}   {st}   {lin:>20s}")
    if args.plots:
        print(f"\nplots: {', '.join(payload['plots'])}")
    return EXIT_OK


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


def _print_sweep(result, label: str, column: int) -> None:
    import numpy as np

    w = max(8, *(len(n) for n in result.source_names))
    print(f"  {label}:")
    print(f"    {'source':{w}s} {'dx [mm]':>9s} {'dy [mm]':>9s} {'dz [mm]':>9s} {'|dP| [mm]':>10s} {'angle [deg]':>12s}")
    for k, name in enumerate(result.source_names):
        e = result.errors[k, column]
        print(f"    {name:{w}s} {e[0] * 1e3:9.4f} {e[1] * 1e3:9.4f} {e[2] * 1e3:9.4f} {e[3] * 1e3:10.4f} "
              f"{np.degrees(e[7]):12.6f}")


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
    from .sensitivity import allocate_tolerance, random_inputs

    if not (args.target_tol > 0 and math.isfinite(args.target_tol)):
        raise InputError(f"--target-tol {args.target_tol}: the tolerance must be a number > 0 [mm]")
    if not (0.0 < args.target_prob < 1.0):
        raise InputError(f"--target-prob {args.target_prob}: the probability must lie strictly between 0 and 1")
    if args.samples < 10:
        raise InputError(f"--samples {args.samples}: need at least 10")
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
    update, close = _progress(None, "tolerance (Monte Carlo runs)", args.quiet)
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
    if args.json is not None:
        emit_json(payload, args.json)
        if args.json == "-":
            return EXIT_OK

    what = ", ".join(main.scaled_groups) if main.scaled_groups else "all"
    print(f"{robot.name}, preset {label}, at {format_joint_values(robot, q)}")
    print(f"Target P(|dP| < {args.target_tol:g} mm) >= {args.target_prob:g}; {args.samples} samples, seed {args.seed}")
    print(f"  with the preset's spreads:  P = {main.nominal_probability:.4f}")
    print(f"  largest factor on the spreads ({what}): {main.factor:.6g}  (P = {main.achieved_probability:.4f})")
    w = max(26, *(len(s.name) for s in main.spreads))
    print(f"  {'source':{w}s} {'group':16s} {'std now':>14s} {'std allowed':>14s}")
    for s in main.spreads:
        scale, unit = (1e3, "mm") if s.unit == "m" else (180.0 / math.pi, "deg")
        print(f"  {s.name:{w}s} {s.group:16s} {s.nominal_std * scale:10.5g} {unit:3s} {s.allowed_std * scale:10.5g} {unit:3s}")
    if args.per_group:
        print("  each group alone (the others at their spreads):")
        for g, a in per_group.items():
            if isinstance(a, str):
                print(f"    {g:16s} impossible: {a}")
            else:
                print(f"    {g:16s} factor {a.factor:.6g}")
    return EXIT_OK


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
    robot = load_robot(args.robot, args.tool)
    if args.file:
        traj = read_trajectory_csv(args.file, robot)
    else:
        if args.steps < 2:
            raise InputError(f"--steps {args.steps}: need at least 2")
        traj = tool_change_motion(robot, n_steps=args.steps)
    sampler, label = _sampler(robot, args)
    update, close = _progress(len(traj), "trajectory", args.quiet)
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
    if args.plots:
        from pathlib import Path

        from .plots_sensitivity import plot_trajectory_bands, plot_trajectory_contributions

        folder = Path(args.plots)
        payload["plots"] = [str(plot_trajectory_bands(bands, folder / "trajectory_error_bands.png",
                                                      f"TCP position error along {traj.source}, preset "
                                                      f"{label}, {args.samples} samples"))]
        if bands.source_names:
            payload["plots"].append(str(plot_trajectory_contributions(
                bands, folder / "trajectory_contributions.png",
                f"First-order std of each error source along {traj.source}, preset {label}")))
    if args.json is not None:
        emit_json(payload, args.json)
        if args.json == "-":
            return EXIT_OK
    lo, hi = bands.quantiles
    print(f"{robot.name}, preset {label}: {traj.source}, {len(traj)} steps over "
          f"{traj.time[-1] - traj.time[0]:g} s, {args.samples} as-built robots, seed {args.seed}")
    print(f"  {'t [s]':>7s} {'std dx':>8s} {'std dy':>8s} {'std dz':>8s} {'(1st order)':>26s} "
          f"{f'|dP| {hi * 100:g} %':>11s}   all [mm]")
    rows = np.unique(np.linspace(0, len(traj) - 1, min(len(traj), 11)).round().astype(int))
    for i in rows:
        s, f = bands.std[i] * 1e3, bands.first_order_std[i] * 1e3
        print(f"  {traj.time[i]:7.2f} {s[0]:8.4f} {s[1]:8.4f} {s[2]:8.4f}   ({f[0]:7.4f} {f[1]:7.4f} {f[2]:7.4f}) "
              f"{bands.norm_upper[i] * 1e3:11.4f}")
    i = int(np.argmax(bands.norm_upper))
    print(f"  largest {hi * 100:g} % quantile of |dP|: {bands.norm_upper[i] * 1e3:.4f} mm at t = {traj.time[i]:g} s")
    if bands.source_names:
        print("  largest first-order contributions (std [mm] of each source alone):")
        for i in np.unique([0, len(traj) // 2, len(traj) - 1]):
            parts = []
            for c, axis in enumerate("xyz"):
                top = np.argsort(-bands.contributions[i, :, c])[:3]
                parts.append(f"{axis}: " + ", ".join(f"{bands.source_names[k]} {bands.contributions[i, k, c] * 1e3:.3f}"
                                                     for k in top if bands.contributions[i, k, c] > 0))
            print(f"    t = {traj.time[i]:g} s  " + " | ".join(parts))
    if args.plots:
        print(f"plots: {', '.join(payload['plots'])}")
    return EXIT_OK
