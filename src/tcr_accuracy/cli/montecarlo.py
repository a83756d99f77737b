"""CLI: ``tcr-accuracy montecarlo``, the seed's Table 3/5 statistics and Eq. (25)-(26).

Heavy imports live inside the run function so that ``--help`` stays instant.
"""

from __future__ import annotations

import math

from .common import (MAX_COUNT, MAX_MM, PRESETS, add_robot_arguments, check_memory, format_joint_values, integer,
                     joint_value, joint_values_si, number, sample_bytes, sampler_from_args, seed_value)
from .output import add_output_arguments, progress_bar

#: What the "dp" column means (also written to the JSON).
DP_DEFINITION = ("signed radial error |P_actual| - |P_nominal| [mm]: change of the TCP's distance "
                 "from the base origin (to first order dP projected on the unit vector to the nominal TCP)")


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "montecarlo", help="Monte Carlo accuracy and reliability of the TCP at one pose",
        description="Samples the error model (the seed's Table 1, Table 2 or Table 4 joint clearance, "
                    "or a TOML/YAML --config file), runs the batched kinematics and prints the TCP "
                    "error statistics of the seed's Table 3/5 (mm and rad), the reliability "
                    "P(|dP| < T) and P(|d angle| < R) of Eq. (25), the first-order (Jacobian) standard "
                    "deviations next to the Monte Carlo ones, and tail probabilities P(|dP| > T) with "
                    "confidence intervals (exact binomial on the counts, first-order Gaussian, and "
                    "importance sampling on the exact model). Joint values: revolute [deg], "
                    "prismatic [mm]; default the robot's working pose.",
    )
    add_robot_arguments(p)
    source = p.add_mutually_exclusive_group()
    source.add_argument("--preset", choices=PRESETS, default=None,
                        help="the seed's error distributions: table1, table2 or clearance (Table 4); default table2 "
                             "for the tool-changer and table1 (built from the robot's own joints) for any other robot")
    source.add_argument("--config", default=None, metavar="FILE",
                        help="TOML or YAML file of error distributions (see docs/monte-carlo.md)")
    p.add_argument("--samples", type=integer(low=2, high=MAX_COUNT), default=20_000,
                   help="Monte Carlo samples (default 20000)")
    p.add_argument("--seed", type=seed_value, default=0, help="random seed (default 0)")
    p.add_argument("--q", nargs="+", type=joint_value, metavar="VALUE",
                   help="joint values: revolute [deg], prismatic [mm] (default: working pose)")
    p.add_argument("--tol", nargs="+", type=number(low=0, low_open=True, high=MAX_MM, unit="mm"),
                   default=[0.15, 0.25], metavar="MM",
                   help="position tolerances T [mm] (default 0.15 0.25)")
    angle = p.add_mutually_exclusive_group()
    angle.add_argument("--angle-tol-deg", type=number(low=0, low_open=True, high=180.0, unit="deg"), default=None,
                       metavar="DEG",
                       help="attitude tolerance R per ZYX angle [deg], like every angle at the command line "
                            "(default 0.1146 deg = the seed's 0.002 rad)")
    angle.add_argument("--angle-tol", type=number(low=0, low_open=True, high=math.pi, unit="rad"), default=0.002,
                       metavar="RAD", help="the same in rad, as the seed states it (default 0.002)")
    p.add_argument("--tail-samples", type=integer(low=0, high=MAX_COUNT), default=20_000, metavar="N",
                   help="importance samples per tolerance for the tail P(|dP| > T) (default 20000; 0: skip)")
    p.add_argument("--chunk", type=integer(low=1, high=MAX_COUNT), default=None, metavar="N",
                   help="samples per chunk (default 20000; part of the random stream)")
    add_output_arguments(p, view=True, json_help="write JSON (keys in docs/monte-carlo.md) to FILE, or to "
                                                 "stdout without FILE")
    p.add_argument("--view-samples", type=integer(low=1, high=MAX_COUNT), default=2000, metavar="N",
                   help="how many of the samples the 3D view's TCP error cloud shows (the first N of the run's; "
                        "default 2000)")
    cluster = p.add_mutually_exclusive_group()
    cluster.add_argument("--dask", default=None, metavar="ADDRESS",
                         help="run the chunks on the Dask scheduler at ADDRESS (e.g. tcp://host:8786)")
    cluster.add_argument("--workers", type=integer(low=1, high=1024), default=None, metavar="N",
                         help="run the chunks on a local Dask cluster of N processes (1 thread each)")
    p.set_defaults(run=_run_montecarlo)


def _check_args(args) -> None:
    """The options' types check each value; here, what depends on two of them."""
    if args.angle_tol_deg is not None:
        args.angle_tol = math.radians(args.angle_tol_deg)  # SI inside


def _client(args):
    """(client, closer) for --dask / --workers, or (None, no-op)."""
    if args.dask is None and args.workers is None:
        return None, lambda: None
    import logging

    from distributed import Client, LocalCluster

    if args.dask is not None:
        try:
            client = Client(args.dask, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:
            from ..exceptions import InputError

            raise InputError(f"--dask {args.dask}: cannot connect ({' '.join(str(exc).split())})") from None
        return client, client.close
    cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.ERROR)
    client = Client(cluster)

    def close():
        client.close()
        cluster.close()

    return client, close


def _tol_key(t_mm: float) -> str:
    return f"{t_mm:g}"


def _run_montecarlo(args) -> int:
    import numpy as np

    from .output import RunOutput
    from ..analysis.montecarlo import CHUNK, STAT_COLUMNS, run_monte_carlo
    from ..model.errors import ErrorBudget, default_preset
    from ..analysis.reliability import binomial_interval, first_order, gaussian_exceedance, importance_exceedance
    from .common import robot_from_args

    _check_args(args)
    out = RunOutput(args, "Monte Carlo accuracy of the TCP")
    robot = robot_from_args(args)
    q = joint_values_si(robot, args.q)
    sampler = sampler_from_args(robot, args.preset, args.config)
    tolerances_m = np.array(args.tol) * 1e-3
    chunk = args.chunk or CHUNK
    per_sample = sample_bytes(robot)
    check_memory(args, f"--samples {args.samples} in chunks of {chunk}",
                 min(chunk, args.samples) * per_sample + -(-args.samples // chunk) * 1000.0)  # + a seed per chunk
    check_memory(args, f"--view-samples {args.view_samples} and --tail-samples {args.tail_samples}",
                 (args.view_samples + args.tail_samples) * per_sample)
    client, close_client = _client(args)
    update, close_bar = progress_bar(args.samples, "monte carlo", args.quiet, unit="sample", unit_scale=True)
    try:
        result = run_monte_carlo(sampler, q, args.samples, args.seed, position_tolerances=tolerances_m,
                                 angle_tolerance=args.angle_tol, chunk=chunk, progress=update, client=client)
    finally:
        close_bar()
        close_client()
    fo = first_order(sampler, q)
    fo_std = {"dx": fo.position_std[0], "dy": fo.position_std[1], "dz": fo.position_std[2],
              "d_alpha_z": fo.euler_std[0], "d_beta_y": fo.euler_std[1], "d_gamma_x": fo.euler_std[2]}
    s = result.stats
    col = {name: k for k, name in enumerate(STAT_COLUMNS)}

    def entry(name, scale):
        k = col[name]
        return {"mean": float(s.mean[k] * scale), "std": float(s.std[k] * scale),
                "max": float(s.maximum[k] * scale), "min": float(s.minimum[k] * scale)}

    tails = {}
    for t_mm, t_m, inside in zip(args.tol, tolerances_m, result.inside_position):
        outside = int(result.n_samples - inside)
        tail = {"monte_carlo": outside / result.n_samples,
                "monte_carlo_ci95": list(binomial_interval(outside, result.n_samples)),
                "first_order": gaussian_exceedance(fo.mean[:3], fo.covariance[:3, :3], float(t_m))}
        if isinstance(sampler, ErrorBudget) and args.tail_samples > 0:
            est = importance_exceedance(sampler, q, float(t_m), args.tail_samples,
                                        np.random.default_rng([args.seed, 1]))
            tail.update({"importance_sampling": est.probability,
                         "importance_sampling_ci95": list(est.ci95),
                         "importance_effective_samples": est.effective_samples,
                         "importance_inflation": est.inflation})
        tails[_tol_key(t_mm)] = tail
    payload = {
        "robot": robot.name,
        "tool_frame": robot.tool_frame,
        "preset": None if args.config else (args.preset or default_preset(robot)),
        "config": args.config,
        "sampler": sampler.name,
        "samples": result.n_samples,
        "seed": args.seed,
        "chunk": chunk,
        "q": {n: float(v * sc) for n, v, sc in zip(robot.joint_names, q, robot.display_scale)},
        "q_units": dict(zip(robot.joint_names, robot.display_units)),
        "q_si": q.tolist(),
        "nominal_position_mm": (result.nominal_position * 1e3).tolist(),
        "stats_mm": {name: entry(name, 1e3) for name in ("dx", "dy", "dz", "dp", "norm")},
        "stats_rad": {name: entry(name, 1.0) for name in ("d_alpha_z", "d_beta_y", "d_gamma_x")},
        "dp_definition": DP_DEFINITION,
        "first_order_std_mm": {k: float(fo_std[k] * 1e3) for k in ("dx", "dy", "dz")},
        "first_order_std_rad": {k: float(fo_std[k]) for k in ("d_alpha_z", "d_beta_y", "d_gamma_x")},
        "reliability_position": {_tol_key(t): float(p) for t, p in zip(args.tol, result.position_reliability)},
        "reliability_position_ci95": {
            _tol_key(t): list(binomial_interval(int(k), result.n_samples))
            for t, k in zip(args.tol, result.inside_position)},
        "angle_tolerance_rad": float(args.angle_tol),
        "reliability_angle": {name: float(p) for name, p in
                              zip(("d_alpha_z", "d_beta_y", "d_gamma_x"), result.angle_reliability)},
        "tail_position": tails,
    }
    from ..view.plots_montecarlo import write_montecarlo_plots

    _report_tables(out, robot, q, sampler, args, result, payload)
    out.add_plots(lambda folder: write_montecarlo_plots(result, folder, label=sampler.name),
                  {"cloud_3d.png": "TCP position error cloud (seed Fig. 6 and 12)",
                   "projection_density.png": "Projection densities of the TCP position error on the xy, xz "
                                             "and yz planes"})
    if out.scene_wanted:
        out.set_scene(*_scene(robot, q, sampler, args, result, chunk))
    return out.finish(payload, lambda: _print_report(robot, q, sampler, args, result, payload))


def _scene(robot, q, sampler, args, result, chunk):
    """The robot at q with the TCP error cloud of the run's own first --view-samples samples (drawn
    again from the run's random stream), coloured by |dP| on the scale of all the samples the
    table counts, and the nominal TCP marked."""
    from ..analysis.montecarlo import drawn_error_vectors
    from ..view.viewer import Scene

    scene = Scene(f"{robot.name}: Monte Carlo of {sampler.name}")
    scene.add_robot(robot, q, "nominal")
    x = drawn_error_vectors(sampler, args.samples, args.seed, chunk=chunk, count=args.view_samples)
    norm = result.column("norm")
    low, high = result.stats.minimum[norm] * 1e3, result.stats.maximum[norm] * 1e3
    magnify = scene.add_tcp_error_cloud(robot, q, x, sampler.error_model, vmin_mm=low, vmax_mm=high)
    scene.add_marker(result.nominal_position, "marked pose", "the nominal TCP at the pose the robot is drawn at",
                     radius_m=0.05)
    scene.add_note(f"the first {len(x)} of the {result.n_samples} samples of the table (seed {args.seed}); colour "
                   f"scale: the least to the largest |dP| of all {result.n_samples}, {low:.4g} to {high:.4g} mm; "
                   f"errors magnified x {magnify:g} about the nominal TCP")
    return scene, f"TCP error cloud at the pose, |dP| magnified x {magnify:g}"


def _setup_lines(robot, q, sampler, args, result, payload) -> list[str]:
    if args.config:
        source = f"--config {args.config} ({sampler.name})"
    elif args.preset:
        source = f"preset {payload['preset']}"
    else:  # say which preset was taken, and why
        source = f"preset {payload['preset']} (the default for " + (
            "the tool-changer's joints)" if payload["preset"] == "table2" else
            f"{robot.name}: the seed's Table 1 spreads on its own joints; the tool-changer's Table 2 does not fit it)")
    return [f"Monte Carlo of {source}: {result.n_samples} samples, seed {args.seed}",
            f"  {robot.name}, TCP '{robot.tool_frame}' at {format_joint_values(robot, q)}",
            "  nominal TCP [mm]: x = {:.3f}, y = {:.3f}, z = {:.3f}".format(*payload["nominal_position_mm"])]


def _stat_rows(payload) -> list[tuple]:
    """(label with unit, {mean, std, max, min}, first-order std or None) of the seed's Table 3/5."""
    rows = [("dp [mm]", payload["stats_mm"]["dp"], None),
            ("dx [mm]", payload["stats_mm"]["dx"], payload["first_order_std_mm"]["dx"]),
            ("dy [mm]", payload["stats_mm"]["dy"], payload["first_order_std_mm"]["dy"]),
            ("dz [mm]", payload["stats_mm"]["dz"], payload["first_order_std_mm"]["dz"]),
            ("|dP| [mm]", payload["stats_mm"]["norm"], None)]
    rows += [(f"{label} [rad]", payload["stats_rad"][key], payload["first_order_std_rad"][key])
             for label, key in (("d_alpha (z)", "d_alpha_z"), ("d_beta (y)", "d_beta_y"),
                                ("d_gamma (x)", "d_gamma_x"))]
    return rows


def _report_tables(out, robot, q, sampler, args, result, payload) -> None:
    out.add_text("\n\n".join(line.strip() for line in _setup_lines(robot, q, sampler, args, result, payload)),
                 heading="Setup")
    out.add_table("TCP error statistics (seed Table 3 and 5)", ["error", "mean", "std", "max", "min", "1st-order std"],
                  [(label, e["mean"], e["std"], e["max"], e["min"], fo) for label, e, fo in _stat_rows(payload)],
                  note="dp = " + DP_DEFINITION)
    rel = [(f"|dP| < {t} mm", payload["reliability_position"][t], *payload["reliability_position_ci95"][t])
           for t in payload["reliability_position"]]
    rel += [(f"|{k}| < {args.angle_tol:g} rad", p, None, None) for k, p in payload["reliability_angle"].items()]
    out.add_table("Reliability, Eq. (25)", ["event", "probability", "95% CI low", "95% CI high"], rel,
                  note="exact binomial (Clopper-Pearson) intervals on the Monte Carlo counts")
    out.add_table("Tail P(|dP| > T) and its complement P(|dP| <= T)",
                  ["T", "estimate", "P(|dP| > T)", "P(|dP| <= T) = 1 - P", "95% interval of 1 - P"],
                  _tail_rows(payload), units=["mm", "", "", "", ""], float_format="{:.3g}",
                  note=_tail_note(result))


def _tail_rows(payload) -> list[tuple]:
    """One row per tolerance and estimate. A tail near 1 reads "1" at any sensible precision,
    so each row also gives the complement, small and informative, with its interval."""
    rows = []
    for key, tail in payload["tail_position"].items():
        lo, hi = tail["monte_carlo_ci95"]
        rows.append((key, "Monte Carlo", tail["monte_carlo"], 1.0 - tail["monte_carlo"],
                     f"[{1.0 - hi:.3g}, {1.0 - lo:.3g}]"))
        rows.append((key, "first-order Gaussian", tail["first_order"], _complement(tail["first_order"]), None))
        if "importance_sampling" in tail:
            ilo, ihi = tail["importance_sampling_ci95"]
            rows.append((key, "importance sampling", tail["importance_sampling"],
                         _complement(tail["importance_sampling"]), f"[{1.0 - ihi:.3g}, {1.0 - ilo:.3g}]"))
    return rows


def _complement(p: float):
    """1 - p, or the words for a complement lost in double-precision rounding."""
    return 1.0 - p if p < 1.0 else "below 1e-16"


def _tail_note(result) -> str:
    """Where the errors lie, so a tolerance far inside or outside the cloud is seen as such."""
    import numpy as np

    norm = np.linalg.norm(result.cloud, axis=1) * 1e3
    q50, q95, q99 = np.quantile(norm, [0.5, 0.95, 0.99])
    return (f"Quantiles of |dP| over the first {len(norm)} samples: median {q50:.3g} mm, 95 % {q95:.3g} mm, "
            f"99 % {q99:.3g} mm; a tolerance well below the median has a tail near 1 (its complement is the "
            "informative figure), one near the 99 % quantile the tail that decides a design")


def _print_report(robot, q, sampler, args, result, payload) -> None:
    print("\n".join(_setup_lines(robot, q, sampler, args, result, payload)))
    print(f"\n  {'error':17s} {'mean':>11s} {'std':>11s} {'max':>11s} {'min':>11s} {'1st-order std':>14s}")
    for label, e, fo in _stat_rows(payload):
        fo_text = f"{fo:14.4e}" if fo is not None else f"{'':14s}"
        print(f"  {label:17s} {e['mean']:11.4e} {e['std']:11.4e} {e['max']:11.4e} {e['min']:11.4e} {fo_text}")
    print("  dp = " + DP_DEFINITION)
    print("\n  Reliability, Eq. (25) (95% exact binomial interval):")
    for t in args.tol:
        key = _tol_key(t)
        lo, hi = payload["reliability_position_ci95"][key]
        print(f"    P(|dP| < {key} mm) = {payload['reliability_position'][key]:.4f}  [{lo:.4f}, {hi:.4f}]")
    ra = payload["reliability_angle"]
    print(f"    P(|d angle| < {args.angle_tol:g} rad = {math.degrees(args.angle_tol):.4g} deg) = "
          f"({ra['d_alpha_z']:.4f}, {ra['d_beta_y']:.4f}, {ra['d_gamma_x']:.4f})  "
          "(alpha about z, beta about y, gamma about x)")
    print("\n  Tail P(|dP| > T): Monte Carlo [95% CI] | first-order Gaussian | importance sampling [95% CI]:")
    for key, tail in payload["tail_position"].items():
        lo, hi = tail["monte_carlo_ci95"]
        text = f"    T = {key} mm: {tail['monte_carlo']:.3e} [{lo:.2e}, {hi:.2e}] | {tail['first_order']:.3e}"
        if "importance_sampling" in tail:
            ilo, ihi = tail["importance_sampling_ci95"]
            text += f" | {tail['importance_sampling']:.3e} [{ilo:.2e}, {ihi:.2e}]"
        print(text)
