"""``tcr-accuracy iso9283 plan --path`` and ``iso9283 evaluate --path``: the ISO 9283 path tests.

``plan --path`` writes the standard's test paths in the cube's plane (a line, two circles, a
rectangle for the corners) as a commanded path CSV: the joints of every sample with ``path``,
``speed_pct``, ``speed_mm_s``, the commanded ``time_s`` and arc length ``s_mm``, and the commanded
TCP ``target_x_mm`` ...; ``evaluate MEAS.csv --path COMMANDED.csv`` reads the tracker's stream and
prints AT, RT, the corner deviations and the path velocity figures, before and (predicted) after
compensation with ``--model``. Registered by :mod:`tcr_accuracy.cli.iso9283`.
"""

from __future__ import annotations

from .common import EXIT_OK, check_csv_memory, emit_json, sample_bytes, status

#: Normal planes along each path when --planes is not given.
PATH_PLANES = 100


def run_path_plan(args) -> int:
    import numpy as np

    from .staging import write_text
    from ..iso9283.path_plan import PATH_CYCLES, plan_path_test
    from .iso9283_inputs import plan_inputs

    robot, home, workspace, conditions, rated = plan_inputs(args)
    top = max(c.load_pct for c in conditions)
    runs = [c for c in conditions if c.load_pct == top]  # the standard: the paths at rated load, three speeds
    centre = None if args.cube_centre_mm is None else np.asarray(args.cube_centre_mm) * 1e-3
    size = None if args.cube_size_mm is None else args.cube_size_mm * 1e-3
    speed = None if args.path_speed_mm_s is None else args.path_speed_mm_s * 1e-3
    from .iso9283_inputs import tool_rotation

    tracker = None if args.tracker_mm is None else np.asarray(args.tracker_mm, dtype=float) * 1e-3
    plan = plan_path_test(robot, args.seed, centre=centre, size=size, home=home, workspace=workspace,
                          rated_speed=speed, tool_rotation=tool_rotation(args), tracker=tracker)
    cycles = args.cycles or PATH_CYCLES
    from pathlib import Path

    text, rows = _path_csv(robot, plan, runs, cycles, rated)
    write_text(Path(args.out), text)
    payload = {"robot": robot.name, "tool": robot.tool_frame, "cube_centre_mm": (plan.cube.centre * 1e3).tolist(),
               "cube_size_mm": plan.cube.size * 1e3, "orientation": plan.cube.orientation,
               "collision": plan.cube.collision, "workspace": plan.cube.workspace,
               "home_display": (plan.cube.home * robot.display_scale).tolist(),
               "rated_speed_mm_s": plan.rated_speed * 1e3, "rated_speed_source": plan.speed_source,
               "speeds_pct": [c.speed_pct for c in runs], "load_pct": top, "rated_load": rated, "cycles": cycles,
               "paths": [{"path": p.name, "length_mm": p.length * 1e3, "samples": len(p.points),
                          "start_mm": (p.points[0] * 1e3).tolist(), "end_mm": (p.points[-1] * 1e3).tolist(),
                          "corners_mm": [(p.points[k] * 1e3).tolist() for k in p.corners]} for p in plan.paths],
               "rows": rows, "out": str(args.out)}
    if args.json:
        emit_json(payload, args.json)
    if args.json != "-":
        print(_path_plan_text(robot, plan, runs, cycles, rated, args))
    status(args, f"path plan written to {args.out}")
    return EXIT_OK


def _path_csv(robot, plan, runs, cycles, rated) -> tuple[str, int]:
    import io

    from ..iso9283.path_plan import trapezoid_times

    joints = [f"{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]
    payload = all(c.payload_kg is not None for c in runs)
    out = io.StringIO()
    out.write(f"# ISO 9283 path test of {robot.name} (TCP {robot.tool_frame}), written by tcr-accuracy iso9283 plan "
              "--path\n")
    out.write(f"# cube centre {', '.join(f'{v * 1e3:.3f}' for v in plan.cube.centre)} mm, edge "
              f"{plan.cube.size * 1e3:.3f} mm; rated path speed {plan.rated_speed * 1e3:.1f} mm/s "
              f"({plan.speed_source}); {rated}\n")
    out.write(f"# run each path and speed {cycles} times through its points in order (time_s: the commanded timing, "
              "trapezoidal); log the tracker's stream with time_s, x_mm, y_mm, z_mm, path, speed_pct, cycle\n")
    out.write(",".join(joints + (["payload_kg"] if payload else []) +
                       ["path", "speed_pct", "speed_mm_s", "time_s", "s_mm", "target_x_mm", "target_y_mm",
                        "target_z_mm"]) + "\n")
    rows = 0
    for path in plan.paths:
        for cond in runs:
            speed = plan.rated_speed * cond.speed_pct / 100.0
            out.write(f"# {path.name}, {path.length * 1e3:.1f} mm, at {cond.speed_pct:g} % ({speed * 1e3:.1f} mm/s)"
                      f"{', corners at samples ' + ', '.join(map(str, path.corners)) if path.corners else ''}\n")
            times = trapezoid_times(path.s, speed)
            for q, t, s, p in zip(path.q, times, path.s, path.points):
                row = [format(v, ".10g") for v in q * robot.display_scale]
                row += [format(cond.payload_kg, ".10g")] if payload else []
                row += [path.name, format(cond.speed_pct, "g"), format(speed * 1e3, ".10g"), format(t, ".10g"),
                        format(s * 1e3, ".10g")] + [format(v * 1e3, ".10g") for v in p]
                out.write(",".join(row) + "\n")
                rows += 1
    return out.getvalue(), rows


def _path_plan_text(robot, plan, runs, cycles, rated, args) -> str:
    cube = plan.cube
    lines = [f"{robot.name}: ISO 9283 test paths in the plane of the test cube (centre "
             f"{', '.join(f'{v * 1e3:.1f}' for v in cube.centre)} mm, edge {cube.size * 1e3:.1f} mm)",
             f"  self-collision   {cube.collision}", f"  workspace        {cube.workspace}",
             f"  line of sight    {cube.sight}" + ("" if cube.tracker is None else " (at the cube's five poses)"),
             f"  rated speed      {plan.rated_speed * 1e3:.1f} mm/s ({plan.speed_source})",
             f"  {'path':<14}{'length [mm]':>12}{'samples':>9}  corners"]
    for path in plan.paths:
        lines.append(f"  {path.name:<14}{path.length * 1e3:12.1f}{len(path.points):9d}  {len(path.corners) or '-'}")
    lines.append(f"  each at {', '.join(f'{c.speed_pct:g} %' for c in runs)} of the rated speed ({rated}), "
                 f"{cycles} cycles -> {args.out}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------
def run_path_evaluate(args) -> int:
    import warnings

    from ..exceptions import InputError
    from ..io.measurements import MeasurementWarning, read_measurements
    from ..io.tracker_stream import read_tracker_stream
    from ..iso9283.evaluate import compensated_readings, register_from
    from ..iso9283.path_evaluate import evaluate_path_test
    from .common import robot_from_args
    from .diagnose import robot_source
    from .iso9283_inputs import read_model
    from .output import RunOutput

    if args.band_mm is not None:
        raise InputError("--band-mm is for pose tests (stabilisation time); a path test has none")
    robot = robot_from_args(args)
    check_csv_memory(args, args.measurements, "MEAS.csv", sample_bytes(robot))
    check_csv_memory(args, args.path, "COMMANDED.csv", sample_bytes(robot))
    model = read_model(robot, args.model) if args.model else None
    with warnings.catch_warnings():  # a commanded path may pass one point twice (a closed circle)
        warnings.filterwarnings("ignore", message=".*repeated pose", category=MeasurementWarning)
        commanded = read_measurements(args.path, robot, require_position=False, repeats_allowed=True)
    stream = read_tracker_stream(args.measurements)
    given = {}
    if args.frame_from:
        calibration = read_measurements(args.frame_from, robot, min_rows=3)
        given = {"registration": register_from(robot, calibration), "registration_source": args.frame_from}
        if model is not None:  # the compensated robot seen from the same poses, compensated alike
            given["registration_after"] = register_from(robot, compensated_readings(
                robot, calibration, given["registration"], *model))
    before, after = evaluate_path_test(robot, commanded, stream, frame=args.frame or "fit",
                                       planes=args.planes or PATH_PLANES,
                                       model=model, **given)
    out = RunOutput(args, f"ISO 9283 path test: {robot.name}")
    text = format_path_evaluation(robot, args, stream, before, after)
    payload = {"measurements": str(args.measurements), "commanded": str(args.path), "robot": robot.name,
               "robot_source": robot_source(args.robot), "tool_frame": robot.tool_frame, "n_readings": len(stream),
               **path_dict(before)}
    if after is not None:
        payload["compensated"] = {"model": str(args.model), "kind": "predicted: the model's displacement at the "
                                  "commanded joints removed from each reading (first order, positions only)",
                                  **path_dict(after)}
    out.add_preformatted(text, "ISO 9283 path figures")
    return out.finish(payload, lambda: print(text))


def _mm(value, scale=1e3):
    return None if value is None else float(value) * scale


def path_dict(result) -> dict:
    """JSON-ready figures of a :class:`~tcr_accuracy.iso9283.path_evaluate.PathEvaluation` (mm, mm/s, %)."""
    import numpy as np

    runs = []
    for run, f in result.runs:
        runs.append({
            "path": run.path, "speed_pct": run.speed_pct, "cycles": f.n_cycles, "planes": len(f.s),
            "at_mm": f.at * 1e3, "at_s_mm": f.at_s * 1e3, "rt_mm": _mm(f.rt), "rt_s_mm": _mm(f.rt_s),
            "speed_mm_s": _mm(f.speed), "v_mean_mm_s": _mm(f.v_mean), "av_pct": _mm(f.av, 100.0),
            "rv_pct": _mm(f.rv, 100.0), "fv_mm_s": _mm(f.fv), "missed_crossings": f.missed,
            "corners": [{"point_mm": (c.point * 1e3).tolist(), "cr_mean_mm": _mm(np.nanmean(c.cr)),
                         "cr_max_mm": _mm(np.nanmax(c.cr)), "co_mean_mm": _mm(np.nanmean(c.co)),
                         "co_max_mm": _mm(np.nanmax(c.co))} for c in f.corners if np.isfinite(c.cr).any()],
        })
    return {"frame": result.frame, "frame_fit": result.how, "runs": runs, "notes": list(result.notes)}


def format_path_evaluation(robot, args, stream, before, after=None) -> str:
    """The printed path figures: one row per path and speed, the corners, the notes."""
    lines = [f"{robot.name}: ISO 9283 path test {args.measurements} against {args.path} ({len(stream)} readings, "
             f"{len(before.runs)} runs)", f"  measurement frame {before.how}"]
    lines += _path_lines(before)
    if after is not None:
        lines += [f"after compensation with {args.model} (predicted: the model's displacement at the commanded joints "
                  "removed from each reading, first order, positions only):"] + _path_lines(after, notes=False)
    return "\n".join(lines)


def _path_lines(result, notes: bool = True) -> list:
    import numpy as np

    def cell(value, width, digits):
        return f"{'-':>{width}}" if value is None else f"{value:{width}.{digits}f}"

    lines = [f"  {'path':<14}{'speed':>7}{'cycles':>7}{'AT_P':>9}{'RT_P':>9}  [mm]{'v_c':>9}{'AV':>8}{'RV':>8}"
             f"  [mm/s, %]{'FV':>8}  [mm/s]"]
    for run, f in result.runs:
        speed = "-" if run.speed_pct is None else f"{run.speed_pct:g} %"
        lines.append(f"  {run.path:<14}{speed:>7}{f.n_cycles:>7}{f.at * 1e3:9.4f}" + cell(_mm(f.rt), 9, 4) + "      " +
                     cell(_mm(f.speed), 9, 1) + cell(_mm(f.av, 100.0), 8, 2) + cell(_mm(f.rv, 100.0), 8, 2) +
                     "           " + cell(_mm(f.fv), 8, 2))
    corners = [(run, c) for run, f in result.runs for c in f.corners if np.isfinite(c.cr).any()]
    if corners:
        lines.append(f"  {'corner':<14}{'speed':>7}  {'at (x, y, z) [mm]':<22}{'CR':>9}{'CR max':>9}{'CO':>9}"
                     f"{'CO max':>9}  [mm, mean and largest over the cycles]")
        for run, c in corners:
            speed = "-" if run.speed_pct is None else f"{run.speed_pct:g} %"
            lines.append(f"  {run.path:<14}{speed:>7}  {', '.join(f'{v * 1e3:.0f}' for v in c.point):<22}"
                         + "".join(f"{v * 1e3:9.4f}" for v in (np.nanmean(c.cr), np.nanmax(c.cr), np.nanmean(c.co),
                                                               np.nanmax(c.co))))
    if notes:
        lines += [f"  note: {n}" for n in result.notes]
    return lines
