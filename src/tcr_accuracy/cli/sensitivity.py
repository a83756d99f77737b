"""CLI: ``tcr-accuracy sensitivity``, which error source matters.

One-at-a-time sweeps (seed Fig. 7-9 and 13-16) and Sobol indices of every source of an
error sampler. Heavy imports live inside the run functions so that ``--help`` stays
instant.
"""

from __future__ import annotations

import math

from .common import (MAX_COUNT, add_sampler_arguments, check_memory, error_sampler, format_joint_values, integer,
                     joint_values_si, sample_bytes)
from .output import RunOutput, add_output_arguments, progress_bar


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "sensitivity", help="which error source matters: sweeps and Sobol indices",
        description="One-at-a-time sweeps as in the seed's Fig. 7-9 (each link length error at "
                    "+-0.02/0.04/0.06 mm, each joint angle error at +-0.02..0.1 deg) and Fig. 13-16 "
                    "(joint clearance offsets and deflections of one joint at a time), then "
                    "first-order and total Sobol indices (SALib) of every source of the --preset "
                    "for dx, dy, dz, |dP| and the attitude errors.",
    )
    add_sampler_arguments(p, pose=True)
    add_output_arguments(p)
    p.add_argument("--sobol-samples", type=integer(low=2, high=MAX_COUNT), default=1024, metavar="N",
                   help="SALib base sample size, a power of two (model runs: N x (sources + 2)); default 1024")
    p.set_defaults(run=_run_sensitivity)


def _si_series(result):
    from ..analysis.sensitivity import OUTPUT_UNITS, OUTPUTS

    return {name: {f"{o}_{u}": result.errors[k, :, i].tolist() for i, (o, u) in enumerate(zip(OUTPUTS, OUTPUT_UNITS))}
            for k, name in enumerate(result.source_names)}


def _sweep_json(result) -> dict:
    return {"values_" + result.unit: result.values.tolist(), "sources": _si_series(result)}


def _run_sensitivity(args) -> int:
    import numpy as np

    from ..exceptions import InputError
    from ..analysis.random_inputs import random_inputs
    from .common import robot_from_args
    from ..analysis.sensitivity import OUTPUT_UNITS, OUTPUTS, clearance_sweeps, seed_sweeps
    from ..analysis.sobol import sobol_indices

    n = args.sobol_samples
    if n < 2 or n & (n - 1):
        raise InputError(f"--sobol-samples {n}: must be a power of two >= 2 (e.g. 512, 1024, 4096)")
    out = RunOutput(args, "Sensitivity of the TCP error to each error source")
    robot = robot_from_args(args)
    q = joint_values_si(robot, args.q)
    sampler, label = error_sampler(robot, args)
    sweeps = seed_sweeps(robot, q)
    clearance = None
    if any(k == "revolute" for k in robot.joint_kinds):
        from ..model.clearance import ClearanceModel

        clearance = clearance_sweeps(ClearanceModel.from_robot(robot), q)
    n_inputs = len(random_inputs(sampler).sources)
    # SALib keeps every model run's inputs and outputs: N (sources + 2) rows of both
    check_memory(args, f"--sobol-samples {n} over {n_inputs} error sources",
                 n * (n_inputs + 2) * (8.0 * (2 * n_inputs + 16) + sample_bytes(robot)))
    update, close = progress_bar(n * (n_inputs + 2), "Sobol", args.quiet)
    try:
        indices = sobol_indices(sampler, q, n_base=n, seed=args.seed, progress=update)
    finally:
        close()
    if np.all(np.isnan(indices.total_order[indices.outputs.index("norm")])):  # no variance to split: 'nan +- nan'
        raise InputError(f"{label}: no error source moves the TCP at this pose (every spread is zero): there is "
                         "no variance for Sobol indices to split; give the sources a spread")

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


def _sensitivity_plots(folder, sweeps, clearance, indices) -> list:
    from pathlib import Path

    from ..view.plots_sensitivity import ATTITUDE_OUTPUTS, POSITION_OUTPUTS, plot_sobol, plot_sweep

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
    return files
