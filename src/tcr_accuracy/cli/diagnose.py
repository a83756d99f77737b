"""``tcr-accuracy diagnose``: the sim-to-real gap of a robot from tracker measurements.

Edge layer: reads the CSV, runs :func:`tcr_accuracy.diagnosis.diagnose.diagnose`, prints the
summary (mm, labelled), writes JSON, the Markdown/HTML report with plots, and the
as-built URDF with the non-geometric effects' parameters in YAML next to it.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from .common import (add_robot_arguments, as_built_file, check_csv_memory, effect_names, effects_side_file, integer,
                     noise_mm_value, output_file, seed_value, status)
from .output import RunOutput, add_output_arguments


#: The diagnosis' progress line; tqdm puts ", " before the postfix, so this reads
#: "diagnose, step 2: trying geometry [00:04]".
PROGRESS_FORMAT = "{desc}{postfix} [{elapsed}]"

def add_parsers(sub) -> None:
    p = sub.add_parser(
        "diagnose", help="where the sim-to-real gap lies, which effect causes it, how far it shrinks",
        description="Fit the tracker frame, break the remaining TCP error down over the workspace, "
                    "rank the effects of the vocabulary by k-fold held-out error (forward selection "
                    "with a paired significance test, then backward elimination), check "
                    "identifiability, and say whether structure remains. Units: mm and deg in what "
                    "is printed, SI in the YAML.",
    )
    p.add_argument("measurements", metavar="MEASUREMENTS.csv", nargs="+",
                   help="measurement CSV (see README); several files are several sessions of one robot (each "
                        "its own tracker frame, the robot's parameters shared), as is a session column")
    add_robot_arguments(p)
    p.add_argument("--effects", default=None, metavar="LIST",
                   help="comma-separated effects to consider (default: the whole vocabulary; frames is "
                        "always in)")
    p.add_argument("--folds", type=integer(low=2, high=1000), default=5,
                   help="k of the k-fold cross-validation (default 5)")
    p.add_argument("--seed", type=seed_value, default=0, help="seed of the fold split and permutation tests")
    p.add_argument("--noise-mm", type=noise_mm_value, default=None,
                   help="the instrument's noise, std per axis [mm]; noise floor = sqrt(3) x this (default: "
                        "estimated from repeated poses, else from the final residual, and said which)")
    p.add_argument("--as-built-urdf", default=None, type=as_built_file, metavar="FILE",
                   help="write the calibrated URDF to FILE and the other effects' parameters to "
                        "FILE with suffix .effects.yaml")
    add_output_arguments(p, view=True)
    p.set_defaults(run=_run_diagnose)


def _check_distinct_poses(path, measurements) -> None:
    """At least three different joint configurations: at one pose (repeated) the TCP error of
    every effect is one constant offset, and a 'diagnosis' would only fit the tracker frame to it."""
    import numpy as np

    from ..exceptions import InputError

    distinct = len(np.unique(measurements.q, axis=0))
    if distinct < 3:
        raise InputError(f"{path}: {len(measurements)} rows at {distinct} distinct pose(s); measure the TCP at "
                         "different joint values (at least 3, better dozens) for anything to be diagnosed")


def _frame_robot(args, frame: str):
    """The robot with its TCP at a frame the measurement file's columns name (``<frame>.x_mm``):
    a frame the robot lacks is the file's fault, named by its column, unless --tool named it."""
    from ..exceptions import InputError
    from ..model.robot import load_robot

    try:
        return load_robot(args.robot, frame)
    except InputError as exc:
        if args.tool == frame or "no such frame" not in str(exc):
            raise
        raise InputError(f"{args.measurements[0]}: column {frame}.x_mm: {str(exc).partition(': ')[2]}") from None


#: Memory [bytes] the diagnosis plans per measurement (see check_csv_memory in _run_diagnose):
#: measured 3.15 GB peak for 100,000 poses of the tool-changer and 0.66 GB for 10,000
#: (scripts/bench_scale.py), about 30 kB a pose beyond the 0.2 GB the libraries take.
DIAGNOSE_ROW_BYTES = 32_000


def _run_diagnose(args) -> int:
    from ..diagnosis.diagnose import diagnose
    from ..exceptions import FixedFrameError, InputError
    from ..io.measurements import join_sessions, measured_frames, read_measurements
    from ..view.plots_diagnose import write_plots
    from ..model.robot import load_robot

    effects = effect_names(args.effects)
    min_rows = max(3 * args.folds, 12)
    files = list(args.measurements)
    if len(set(map(str, files))) < len(files):
        raise InputError(f"MEASUREMENTS.csv: {next(f for f in files if files.count(f) > 1)} is given twice")
    # the diagnosis holds each measurement's Jacobians over the whole effect vocabulary and
    # the error maps of the pose-dependent effects
    for path in files:
        check_csv_memory(args, path, "diagnosing", DIAGNOSE_ROW_BYTES)
    frames = measured_frames(files[0])
    for path in files[1:]:
        if measured_frames(path) != frames:
            raise InputError(f"{path}: measures {', '.join(measured_frames(path)) or 'the TCP'}, {files[0]} "
                             f"{', '.join(frames) or 'the TCP'}: sessions must measure the same frames")
    labels = _session_labels(files)
    per_file = 3 if len(files) > 1 else min_rows  # a session needs 3 rows for its frame; the whole set more
    if frames:  # several measured frames per row: one chain each, their shared parameters fitted once
        if args.tool is not None and args.tool not in frames:
            raise InputError(f"--tool {args.tool}: {files[0]} measures {', '.join(frames)}")
        order = [args.tool] + [f for f in frames if f != args.tool] if args.tool else frames
        robots, fixed = [], {}
        for f in order:  # a frame no joint moves is a base reference: it watches the tracker, not the robot
            try:
                robots.append(_frame_robot(args, f))
            except FixedFrameError as exc:
                if f == args.tool:
                    raise
                fixed[f] = exc.position
        if not robots:
            raise InputError(f"{files[0]}: every measured frame ({', '.join(order)}) is fixed to the base; "
                             "measure at least one frame a joint moves")
        moving = [f for f in order if f not in fixed]
        parts = [(r, join_sessions([read_measurements(path, r, min_rows=per_file, frame=f) for path in files],
                                   labels)) for r, f in zip(robots, moving)]
        references = [(f, position, join_sessions([read_measurements(path, robots[0], min_rows=per_file, frame=f,
                                                                     check_units=False) for path in files],
                                                  labels))
                      for f, position in fixed.items()]
        robot, measurements, data = robots[0], parts[0][1], parts
    else:
        robot = load_robot(args.robot, args.tool)
        measurements = data = join_sessions([read_measurements(path, robot, min_rows=per_file) for path in files],
                                            labels)
        references = []
    if len(measurements) < min_rows:
        raise InputError(f"{', '.join(map(str, files))}: {len(measurements)} measurement rows, at least {min_rows} "
                         f"are needed for {args.folds}-fold cross-validation")
    _check_distinct_poses(", ".join(map(str, files)), measurements)
    out = RunOutput(args, f"Sim-to-real gap diagnosis: {robot.name}")
    from tqdm import tqdm

    bar = tqdm(desc="diagnose", file=sys.stderr, bar_format=PROGRESS_FORMAT,
               disable=args.quiet or not sys.stderr.isatty())
    try:
        result = diagnose(robot, data, effects=effects, folds=args.folds, seed=args.seed,
                          tracker_noise=None if args.noise_mm is None else args.noise_mm * 1e-3,
                          references=[(f, p, m.position, m.time_s) for f, p, m in references],
                          progress=bar.set_postfix_str)
    finally:
        bar.close()
    payload = jsonable({"measurements": ", ".join(map(str, files)), "robot_source": robot_source(args.robot),
                        "tool_frame": robot.tool_frame, **result.to_dict(robot)})
    source = ", ".join(map(str, files))
    _report_tables(out, robot, result, source)
    out.add_plots(lambda folder: list(write_plots(result, robot, folder).values()), PLOT_CAPTIONS)
    if out.scene_wanted:
        out.set_scene(_scene(robot, result, measurements),
                      "Measured TCP points (base frame) and the gap to the nominal model, magnified; "
                      "nominal robot and the calibrated as-built robot (geometric errors magnified)")
    if args.as_built_urdf:
        urdf, side = write_as_built(robot, result, Path(args.as_built_urdf))
        status(args, f"as-built URDF written to {urdf} (its other effects and the tracker frame: {side})")
    return out.finish(payload, lambda: print(format_summary(robot, result, source)))


def _session_labels(files) -> list[str]:
    """One session label per file: its name without the suffix, made unique."""
    labels = []
    for path in files:
        stem = Path(path).stem or "session"
        label, k = stem, 2
        while label in labels:
            label, k = f"{stem}_{k}", k + 1
        labels.append(label)
    return labels


def robot_source(source) -> str:
    """How to load the robot again: its example-robot-data name, ``tool_changer``, or the URDF's
    absolute path."""
    from ..model.robot import EXAMPLE_ROBOTS

    if source is None or source == "tool_changer" or str(source) in EXAMPLE_ROBOTS:
        return "tool_changer" if source is None else str(source)
    return str(Path(source).resolve())


def jsonable(value):
    """Plain JSON types; non-finite floats become None."""
    import numpy as np

    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


# ---------------------------------------------------------------------------------------
# Printed summary
# ---------------------------------------------------------------------------------------
def format_summary(robot, d, source: str) -> str:
    import numpy as np

    mm = 1e3
    out = [f"Diagnosis of {source}: {d.n_measurements} measurements of {robot.name}, "
           f"{d.folds}-fold cross-validation"]
    out.append(f"\n1. Gap after fitting the tracker frame and TCP offset (frames): "
               f"mean {d.gap.mean * mm:.4f} mm, RMS {d.gap.rms * mm:.4f} mm, max {d.gap.max * mm:.4f} mm")
    if d.sessions:
        out.append(f"   {len(d.sessions)} sessions, each with its own tracker frame (the robot's parameters shared):")
        for s in d.sessions:
            t = s["temperature_c"]
            out.append(f"     {s['session']:20s} {s['n_measurements']:6d} rows, gap RMS {s['gap']['rms_mm']:.4f} mm, "
                       f"final held-out RMS {s['heldout']['rms_mm']:.4f} mm, temperature {t[0]:.1f} to {t[1]:.1f} degC")
    for drift in d.drift:
        key = "drift_mm_per_h" if "drift_mm_per_h" in drift else "drift_mm_per_100_rows"
        unit = "mm/h" if key == "drift_mm_per_h" else "mm per 100 rows"
        speed = float(np.linalg.norm(drift[key]))
        out.append(f"   tracker drift seen by {', '.join(drift['references'])} (session {drift['session']}, in "
                   f"{drift['time_axis']}): {speed:.4f} +- {drift['drift_std_mm_per_unit']:.4f} {unit}, "
                   f"{drift['moved_over_session_mm']:.4f} mm over the session, z = {drift['z']:.1f}: "
                   + ("corrected" if drift["corrected"] else "not corrected (within the noise)"))
    out.append("\n2. Where it lies (residual after frames)")
    axes = d.where["per_axis"]
    out.append("   per axis RMS [mm]: " + ", ".join(f"{a} {axes[a]['rms_mm']:.4f}" for a in "xyz"))
    strongest = _strongest(d.where)
    if strongest:
        out.append("   strongest links: " + "; ".join(strongest))
    along = d.where["along_joints"]
    out.append("   along single joints (share of the residual variance its k-NN along that joint predicts; "
               "short-lag semivariance, 1 = none): " + ", ".join(
                   f"{j} {a['knn_explained_share']:+.2f} ({min(a['short_lag_semivariance_xyz']):.2f})"
                   for j, a in along.items()))
    out.append("   varies most along: " + (", ".join(d.where["varies_along"]) or
                                           "no single joint (the error depends on several together)"))
    pairs = [p for p in d.where.get("along_joint_pairs", []) if p["knn_explained_share"] > 0.05][:3]
    if pairs:
        out.append("   joint pairs it varies along (k-NN share): " + ", ".join(
            f"{'+'.join(p['joints'])} {p['knn_explained_share']:+.2f}" for p in pairs))
    out.append("\n3. Which effect: each effect added to frames alone (held-out RMS [mm], gain, paired z)")
    for name, c in d.candidates.items():
        if c.get("tried"):
            out.append(f"   {name:18s} {c['heldout_rms_mm_with_frames']:9.4f} {c['gain_mm']:+9.4f} "
                       f"z = {c['z']:6.1f}  ({c['n_parameters']} identifiable parameters)")
        else:
            out.append(f"   {name:18s} not tried: {c['why']}")
    ident = d.identifiability
    removed = [(e, r) for e, info in ident["effects"].items() for r in info["removed"]]
    everything = ident.get("all_effects", {})
    out.append(f"   identifiability of the final model: {ident.get('rank', 0)} parameters kept, condition number "
               f"{ident.get('condition_number', float('nan')):.3g}; {len(removed)} removed, e.g.:")
    for e, r in removed[:6]:
        out.append(f"     {r['parameter']}: {r['reason']}")
    if everything:
        n_removed = sum(len(i["removed"]) for i in everything["effects"].values())
        out.append(f"   (whole vocabulary in one model: {everything.get('rank', 0)} identifiable, {n_removed} removed, "
                   f"condition number {everything.get('condition_number', float('nan')):.3g})")
    out.append("\n4. How far it shrinks (k-fold held-out, in the order the effects explain the data) [mm]")
    out.append(f"   {'step':18s} {'params':>6s} {'train RMS':>10s} {'mean':>9s} {'RMS':>9s} {'max':>9s}"
               f"   gain in RMS [95 % interval]")
    for i, s in enumerate(d.steps):
        label = s.effect if i == 0 else "+" + s.effect
        gain = "" if s.gain is None else f"   {s.gain[0] * mm:+.4f} [{s.gain[1] * mm:+.4f}, {s.gain[2] * mm:+.4f}]"
        out.append(f"   {label:18s} {s.n_parameters:6d} {s.train_rms * mm:10.4f} {s.heldout.mean * mm:9.4f} "
                   f"{s.heldout.rms * mm:9.4f} {s.heldout.max * mm:9.4f}{gain}")
    if d.leave_one_out:
        out.append("   leave one out of the chosen set (held-out RMS without it; the others refitted and free to "
                   "take its place / held to their own parameters, own share [95 % interval]):")
        for r in d.leave_one_out:
            low, high = r["own_share_interval_mm"]
            out.append(f"     without {r['dropped']:18s} {r['heldout_rms_mm']:9.4f} ({r['increase_mm']:+.4f})  /  "
                       f"{r['own_share_heldout_rms_mm']:9.4f} ({r['own_share_increase_mm']:+.4f} "
                       f"[{low:+.4f}, {high:+.4f}])")
    for e in d.eliminated:
        out.append(f"   dropped again in backward elimination: {e['effect']} (z = {e['z']:.1f})")
    for swap in d.swaps:
        out.append(f"   swapped after forward selection: {swap['in']} for {swap['out']} (as good held out, fewer "
                   f"parameters: {swap['n_parameters'][swap['in']]} against {swap['n_parameters'][swap['out']]})")
    if d.ambiguous:
        out.append("   the data cannot tell apart (each swapped for the chosen one and refitted; held-out RMS, "
                   "parameters):")
        for group in d.ambiguous:
            members = ", ".join(f"{m['effect']} {m['heldout_rms_mm']:.4f} mm / {m['n_parameters']}"
                                for m in group["members"])
            out.append(f"     {{{', '.join(group['effects'])}}}: {members}")
    out.append(f"   primary effect: {_primary_text(d)}")
    selection = d.selection
    if selection.get("frequency"):
        chosen = [e for e in d.selected_effects if e != "frames"]
        others = [e for e, f in selection["frequency"].items() if e not in chosen and f > 0]
        out.append(f"   stability: chosen in {selection['n_replays']} bootstrap replays of the selection: "
                   + (", ".join(f"{e} {selection['frequency'].get(e, 0.0):.0%}" for e in chosen) or "nothing")
                   + (" (also chosen: " + ", ".join(f"{e} {selection['frequency'][e]:.0%}" for e in others) + ")"
                      if others else ""))
    out.extend(_parameter_lines(d))
    final = d.steps[-1].heldout.rms
    noise = d.noise
    source = "tracker" if noise is None or noise.source == "given" else f"estimated from the {noise.source}"
    if noise is not None and not noise.independent:
        out.append(f"   final held-out RMS {final * mm:.4f} mm; noise floor at most {d.noise_floor * mm:.4f} mm "
                   f"({source} {d.tracker_noise * mm:.4f} mm per axis: an upper bound, so no verdict against it)")
    else:
        out.append(f"   final held-out RMS {final * mm:.4f} mm = {final / d.noise_floor:.2f} x the noise floor "
                   f"{d.noise_floor * mm:.4f} mm ({source} {d.tracker_noise * mm:.4f} mm per axis)")
    if noise is not None and noise.source != "given":
        out.append(f"   noise: {noise.detail}")
    st = d.structure
    along = ", ".join(robot.joint_names[j] for j in st.get("along_joints", []))
    out.append(f"   structure remains: {_verdict_text(d)} (k-NN along {along}: share "
               f"{st['gain_over_null']:+.3f} "
               f"beyond chance, z = {st['z']:.1f}; ridge on joint features share {st['ridge_explained_share']:+.3f}, "
               f"z = {st['ridge_z']:.1f}; limits: share > {st['min_explained']}, p < {st['alpha']})")
    power = st.get("power", {})
    if power:
        seen, n = power.get("smallest_detectable_mm"), _tested_poses(power)
        shapes = ", ".join(power.get("per_shape_mm", {}))
        if seen is not None:
            text = f"with {n} poses the test sees a leftover from {seen:.4g} mm RMS (the largest over {shapes})"
        else:
            unseen = ", ".join(k for k, v in power.get("per_shape_mm", {}).items() if v is None)
            text = f"with {n} poses the leftover of {unseen} goes unseen up to {power['largest_probed_mm']:.4g} mm"
        out.append(f"   power: {text}" + (f"; {st['reason']}" if st.get("verdict") == "cannot tell" else ""))
    sc = d.scatter
    if sc.get("tested", True):
        out.append(f"   random scatter beyond the tracker: {'YES' if sc['detected'] else 'no'} "
                   f"(estimated {sc['estimated_noise_per_axis_mm']:.4f} mm per axis, ratio {sc['ratio']:.2f})")
    else:
        out.append(f"   random scatter beyond the instrument: not tested ({sc['why']})")
    if d.orientation:
        o = d.orientation
        out.append(f"   orientation (held-out): mean {o['heldout_mean_deg']:.4f} deg, "
                   f"RMS {o['heldout_rms_deg']:.4f} deg, max {o['heldout_max_deg']:.4f} deg "
                   f"(weight {o['weight_m_per_rad'] * 1e3:.4g} mm/rad)")
    for frame, stats in d.heldout_by_frame.items():
        out.append(f"   measured frame {frame}: held-out mean {stats.mean * mm:.4f} mm, RMS {stats.rms * mm:.4f} mm, "
                   f"max {stats.max * mm:.4f} mm")
    if st["remains"]:
        out.append("   -> something the vocabulary does not express is still in the data: the fit is not the "
                   "whole story")
    for note in d.notes:
        out.append(f"   note: {note}")
    return "\n".join(out)


def _parameter_lines(d, per_effect: int = 4) -> list[str]:
    import numpy as np

    """The fitted parameters, the largest of each effect (relative to its standard error),
    with unit, standard error, 95 % interval and physical range."""
    import numpy as np

    if not d.parameter_table:
        return []
    out = ["   fitted parameters (value +- standard error, 95 % interval, physical range; SI units; all in the JSON "
           "and the report):"]
    for e, table in d.parameter_table.items():
        if e == "frames":
            continue
        units = d.parameter_units.get(e, {})
        names = sorted(table["values"], key=lambda n: -abs(table["values"][n]))[:per_effect]
        out.append(f"     {e} ({len(table['values'])} parameters; {d.physics.get(e, '')})")
        for n in names:
            v, s = table["values"][n], table["std"][n]
            low, high = table["interval"][n]
            lo, hi = table["range"][n]
            out.append(f"       {n} = {v:+.4g} +- {s:.2g} {units.get(n, '')} [{low:+.3g}, {high:+.3g}], "
                       f"range {lo:.3g} to {hi:.3g}")
        for joint, band in d.joint_function_bands.get(e, {}).items():
            values = table["values"]
            amplitude = {}
            for name, v in values.items():
                parts = name.split(".")
                if parts[1] == joint:
                    order = int(parts[-1][1:])
                    amplitude[order] = amplitude.get(order, 0.0) + v * v
            top = max(amplitude, key=amplitude.get) if amplitude else None
            out.append(f"       {joint}: {np.sqrt(np.mean(band['value_rad'] ** 2)) * 1e6:.1f} urad RMS over "
                       f"{np.degrees(band['angle_rad'][0]):.0f} to {np.degrees(band['angle_rad'][-1]):.0f} deg "
                       f"(band +-{1.96 * np.mean(band['std_rad']) * 1e6:.1f} urad)"
                       + (f", strongest {top} cycles per revolution" if top else ""))
        if table["pinned"]:
            out.append(f"       held on a physical bound: " + ", ".join(
                f"{p['parameter']} ({p['bound']})" for p in table["pinned"][:6])
                + (f" and {len(table['pinned']) - 6} more" if len(table["pinned"]) > 6 else ""))
    return out


def _primary_text(d) -> str:
    if d.primary_effect:
        return f"{d.primary_effect} (the largest own share)"
    if len(d.primary_group) > 1:
        largest = d.primary_tied[0] if d.primary_tied else d.primary_group[0]
        tied = [e for e in d.primary_tied[1:] if e in d.primary_group]
        stand_ins = [e for e in d.primary_group if e not in tied and e != largest]
        share = {r["dropped"]: r["own_share_increase_mm"] for r in d.leave_one_out}
        why = []
        if stand_ins:
            why.append(f"{', '.join(stand_ins)} explain the data as well: measure poses that separate them, "
                       "see plan-poses")
        if tied:
            why.append("own shares not ranked apart by the held-out rows: " + ", ".join(
                f"{e} +{share[e]:.4g} mm" for e in [largest, *tied]))
        return (f"one of {{{', '.join(d.primary_group)}}} (the largest own share is {largest}'s, but "
                + "; ".join(why) + ")")
    return "none beyond frames"


def _verdict_text(d) -> str:
    st = d.structure
    verdict = st.get("verdict", "yes" if st["remains"] else "no")
    tested = _tested_poses(st.get("power") or {"n_poses": d.n_measurements})
    return {"yes": "YES", "no": "no", "cannot tell": f"cannot tell with {tested} poses"}[verdict]


def _tested_poses(power: dict) -> str:
    """"2000" or, when the structure test ran on a random subset, "20000 of the 100000"."""
    n, of = power["n_poses"], power.get("of_poses", power["n_poses"])
    return f"{n}" if of == n else f"{n} (a random subset) of the {of}"


def _strongest(where: dict) -> list:
    links = []
    for group, label in (("joints", "joint"), ("gravity_torque", "gravity torque")):
        for name, info in where.get(group, {}).items():
            if "correlation_xyz" not in info:
                continue
            corr = info["correlation_xyz"]
            c = int(max(range(3), key=lambda k: abs(corr[k])))
            links.append((abs(corr[c]), f"{label} {name} vs {'xyz'[c]}: r = {corr[c]:+.2f}, "
                                        f"binned spread {info['spread_mm']:.3f} mm"))
    for key in ("payload_kg", "temperature_c"):
        if key in where:
            corr = where[key]["correlation_xyz"]
            c = int(max(range(3), key=lambda k: abs(corr[k])))
            links.append((abs(corr[c]), f"{key} vs {'xyz'[c]}: r = {corr[c]:+.2f}"))
    for name, info in where.get("approach_direction", {}).items():
        links.append((0.0, f"approach direction {name}: +/- differ by {info['difference_norm_mm']:.4f} mm"))
    links.sort(key=lambda t: -t[0])
    return [text for _, text in links[:4]]


# ---------------------------------------------------------------------------------------
# As-built model
# ---------------------------------------------------------------------------------------
def write_as_built(robot, d, path: Path) -> tuple[Path, Path]:
    import numpy as np
    import yaml

    from ..model.asbuilt import as_built_urdf
    from ..atomic import write_text_atomically
    from ..effects import effect_class
    from ..model.errors import ErrorModel

    text, tool_frame = as_built_urdf(robot, d.as_built_x, ErrorModel(robot), name=f"{robot.name}_as_built")
    write_text_atomically(path, text)
    side = effects_side_file(path)
    doc = {
        "robot": robot.name,
        "urdf": path.name,
        "tool_frame": tool_frame,
        "units": "SI (m, rad, rad/Nm, m/N, 1/K)",
        "note": "geometric effects (frames' TCP offset, joint offsets, geometry) are built into the URDF; "
                "the tracker frame is not part of the robot and is given separately",
        "tracker_from_base": [[float(v) for v in row] for row in d.tracker_transform],
        **({"measured_frames": list(d.frames_measured),
            "chain_in_urdf": f"the URDF is the chain to {d.frames_measured[0]}; the other frames' TCP offsets "
                             "are among the parameters"} if len(d.frames_measured) > 1 else {}),
        "selected_effects": list(d.selected_effects),
        "effects": {e: {"parameters": {k: float(v) for k, v in p.items()},
                        "units": dict(d.parameter_units.get(e, {})), **_uncertainty(d, e)}
                    for e, p in d.parameters.items() if not effect_class(e).geometric},
        "geometric_parameters_in_urdf": {e: {"parameters": {k: float(v) for k, v in p.items()},
                                             "units": dict(d.parameter_units.get(e, {})), **_uncertainty(d, e)}
                                         for e, p in d.parameters.items() if effect_class(e).geometric},
        **({"joint_functions": {e: {j: {"angle_deg": np.round(np.degrees(b["angle_rad"][::4]), 3).tolist(),
                                          "error_rad": b["value_rad"][::4].tolist(),
                                          "std_rad": b["std_rad"][::4].tolist()}
                                      for j, b in joints.items()}
                                  for e, joints in d.joint_function_bands.items()},
            "joint_functions_note": "each joint's fitted error against its own angle over the measured range (add "
                                    "error_rad to the joint's angle; interpolate between rows)"}
           if d.joint_function_bands else {}),
        "uncertainty_note": "std: standard error from the fit's Jacobian and residual (noise only, not model "
                            "error); interval_95: value +- 1.96 std cut to the physical range; physical_range: "
                            "where the effect's parameters can lie on a real robot, the fit stays inside it",
    }
    write_text_atomically(side, yaml.safe_dump(doc, sort_keys=False))
    return path, side


def _uncertainty(d, effect: str) -> dict:
    """An effect's standard errors, 95 % intervals, physical range and what the bounds hold (YAML-ready)."""
    table = d.parameter_table.get(effect)
    if not table:
        return {}
    finite = lambda v: float(v) if math.isfinite(v) else None  # noqa: E731
    out = {"std": {k: finite(v) for k, v in table["std"].items()},
           "interval_95": {k: [finite(a), finite(b)] for k, (a, b) in table["interval"].items()},
           "physical_range": {k: [finite(a), finite(b)] for k, (a, b) in table["range"].items()},
           "physics": d.physics.get(effect, "")}
    if table["pinned"]:
        out["held_on_physical_bound"] = [dict(p) for p in table["pinned"]]
    return out


# ---------------------------------------------------------------------------------------
# Report tables and 3D view (the report itself is written by cli_output.RunOutput)
# ---------------------------------------------------------------------------------------
PLOT_CAPTIONS = {
    "steps.png": "How far the gap shrinks: held-out RMS after each step, in the order the effects explain the data",
    "axes.png": "Residual after fitting the tracker frame, per axis",
    "joints.png": "Residual after the tracker frame against each joint value",
    "gravity.png": "Residual after the tracker frame against the gravity torque of each joint",
    "regions.png": "Residual after the tracker frame over the workspace (octants, radius, height) and against "
                   "payload, temperature and approach direction",
    "semivariograms.png": "Per-joint semivariograms of the residual (along which joints it varies)",
    "cyclic_joints.png": "Cyclic joint errors: each joint's fitted error against its own angle, with its 95 % band",
}


def _report_tables(out, robot, d, source: str) -> None:
    mm = 1e3
    out.add_text(f"{d.n_measurements} measurements of {robot.name} from {source}, {d.folds}-fold "
                 "cross-validation. Every held-out figure comes from measurements not used for that fit.",
                 heading="Data")
    out.add_table("1. Gap after fitting only the tracker frame and TCP offset", ["statistic", "value"],
                  [("mean", d.gap.mean * mm), ("RMS", d.gap.rms * mm), ("max", d.gap.max * mm)],
                  units=["", "mm"])
    axes = d.where["per_axis"]
    out.add_table("2. Where it lies: residual per axis", ["axis", "RMS"],
                  [(a, axes[a]["rms_mm"]) for a in "xyz"], units=["", "mm"],
                  note="strongest links: " + "; ".join(_strongest(d.where)))
    rows = []
    for name, c in d.candidates.items():
        if c.get("tried"):
            rows.append((name, c["heldout_rms_mm_with_frames"], c["gain_mm"], c["z"], c["n_parameters"]))
        else:
            rows.append((name, "not tried", c["why"], "", ""))
    out.add_table("3. Which effect: each effect added to frames alone",
                  ["effect", "held-out RMS", "gain", "paired z", "identifiable parameters"], rows,
                  units=["", "mm", "mm", "", ""])
    noise_said = (f"noise floor at most {d.noise_floor * mm:.4f} mm (from the residual: an upper bound)"
                  if d.noise is not None and not d.noise.independent else
                  f"final held-out RMS = {d.steps[-1].heldout.rms / d.noise_floor:.2f} x the noise floor "
                  f"{d.noise_floor * mm:.4f} mm")
    out.add_table("4. How far it shrinks (k-fold held-out, in the order the effects explain the data)",
                  ["step", "parameters", "train RMS", "held-out mean", "held-out RMS", "held-out max", "gain",
                   "gain 95 % interval"],
                  [(s.effect if i == 0 else "+" + s.effect, s.n_parameters, s.train_rms * mm, s.heldout.mean * mm,
                    s.heldout.rms * mm, s.heldout.max * mm, "" if s.gain is None else s.gain[0] * mm,
                    "" if s.gain is None else f"{s.gain[1] * mm:+.4f} to {s.gain[2] * mm:+.4f}")
                   for i, s in enumerate(d.steps)],
                  units=["", "", "mm", "mm", "mm", "mm", "mm", "mm"],
                  note=f"primary effect: {_primary_text(d)}; {noise_said}; structure remains: {_verdict_text(d)} "
                       f"({d.structure.get('reason', '')}); stability (share of {d.selection.get('n_replays', 0)} "
                       "bootstrap replays of the selection that chose each effect): " + ", ".join(
                           f"{e} {f:.0%}" for e, f in d.selection.get("frequency", {}).items() if f > 0))
    rows = []
    for e, table in d.parameter_table.items():
        units = d.parameter_units.get(e, {})
        for name, value in table["values"].items():
            low, high = table["interval"][name]
            lo, hi = table["range"][name]
            pinned = any(p["parameter"] == name for p in table["pinned"])
            rows.append((name, f"{value:+.4g}", f"{table['std'][name]:.2g}", f"{low:+.4g} to {high:+.4g}",
                         units.get(name, ""), f"{lo:.3g} to {hi:.3g}" + (" (held on a bound)" if pinned else "")))
    if rows:
        out.add_table("Fitted parameters", ["parameter", "value", "standard error", "95 % interval", "unit",
                                            "physical range"], rows,
                      note="standard errors from the fit's Jacobian and residual (the noise, not model error); the "
                           "fit stays inside each effect's physical range: " + "; ".join(
                               f"{e}: {why}" for e, why in d.physics.items() if why))
    for finding in d.outside_physics:
        out.add_text(f"{finding['description']} (with {finding['effect']} unbounded the held-out RMS would be "
                     f"{finding['heldout_rms_mm']:.4g} mm instead of {finding['heldout_rms_bounded_mm']:.4g} mm)",
                     heading="What the data fit only outside physics")
    if d.ambiguous:
        out.add_table("What the data cannot tell apart",
                      ["group", "member", "held-out RMS", "held-out mean", "parameters", "z (worse than chosen)"],
                      [("{" + ", ".join(g["effects"]) + "}", m["effect"], m["heldout_rms_mm"], m["heldout_mean_mm"],
                        m["n_parameters"], m["z_worse_than_chosen"]) for g in d.ambiguous for m in g["members"]],
                      units=["", "", "mm", "mm", "", ""],
                      note="each chosen effect swapped for each unchosen one (with a companion effect where it "
                           "needs one) and refitted: a member is no significantly worse than the chosen one (paired "
                           "z < the selection threshold) yet explains significantly more than neither. "
                           "tcr-accuracy plan-poses suggests poses that separate them.")
    if d.leave_one_out:
        out.add_table("Leave one out of the chosen set",
                      ["dropped", "held-out RMS (others refitted)", "increase", "held-out RMS (own share)",
                       "increase (own share)"],
                      [(r["dropped"], r["heldout_rms_mm"], r["increase_mm"], r["own_share_heldout_rms_mm"],
                        r["own_share_increase_mm"]) for r in d.leave_one_out],
                      units=["", "mm", "mm", "mm", "mm"],
                      note="others refitted: the remaining effects may take the dropped one's place (backward "
                           "elimination uses this); own share: they keep the parameters they have in the final "
                           "model, so an effect is not credited with what a later one of the vocabulary duplicates. "
                           "The primary effect has the largest own share.")
    out.add_preformatted(format_summary(robot, d, source), heading="Full printed summary")


def _scene(robot, d, measurements):
    """Everything in the robot's base frame: the nominal robot, the calibrated as-built robot as a
    ghost, the measured points (the fitted tracker frame applied), the nominal TCPs at the
    measured joints, the gap to the model, and the tracker's own frame as a triad."""
    import numpy as np

    from ..model.errors import ErrorModel
    from ..model.kinematics import tcp_poses
    from ..view.viewer import (COLORS, Scene, data_extent, frame_axis_length, ghost_magnification, point_size,
                               rotate_vectors, segment_magnification, transform_points)

    base_M_tracker = np.linalg.inv(d.tracker_transform)
    context = measurements.context()
    model_final = transform_points(base_M_tracker, d.predict(robot, d.q, context))  # the fitted model's TCP
    measured = model_final - rotate_vectors(base_M_tracker, d.final_residual)
    nominal_model = measured + rotate_vectors(base_M_tracker, d.gap_residual)  # tracker frame and TCP offset only
    gap = np.linalg.norm(d.gap_residual, axis=1)
    extent = data_extent(measured)
    magnify = segment_magnification(float(gap.max()), extent)
    scene = Scene(f"{robot.name}: sim-to-real gap", frame="data")
    # the robot reaching into the middle of its measurements stands among them, not beside them
    shown = int(np.argmin(np.linalg.norm(measured - np.median(measured, axis=0), axis=1)))
    q_show = d.q[shown]
    row = int(measurements.rows[shown]) if len(getattr(measurements, "rows", ())) == len(d.q) else shown + 2
    scene.add_robot(robot, q_show, name=f"nominal robot at measurement row {row}, the one nearest "
                                        "the middle of the data")
    em = ErrorModel(robot)
    x = np.asarray(d.as_built_x, dtype=float)
    tool = np.zeros_like(x)
    tool[em.tool_slice] = x[em.tool_slice]  # the measured frame's offset: drawn at its true size
    ghost = ghost_magnification(robot, q_show, em, x - tool, magnify)
    as_built = em.perturbed_robot(ghost * (x - tool) + tool)
    scene.add_robot(as_built, q_show, name=f"as-built robot, geometric errors x {ghost:g}, TCP offset x 1",
                    color=(0.85, 0.2, 0.2), opacity=0.35, include_base=False, framed=False)
    scene.add_point_cloud(measured, gap * 1e3, name="measured", size_m=point_size(extent),
                          label="measured points (tracker frame fitted, base frame), coloured by the gap after the "
                                "tracker frame |dP| [mm]")
    scene.add_points(tcp_poses(robot, d.q).position, "nominal TCP", COLORS["nominal_tcp"],
                     size_m=0.5 * point_size(extent), label="nominal TCP (URDF) at the measured joints")
    scene.add_error_segments(measured, nominal_model, magnify=magnify, name="gap", start_color=None,
                             size_m=0.6 * point_size(extent), start_label="measured point",
                             end_label="model with the tracker frame and TCP offset only")
    scene.add_frame(base_M_tracker, "tracker frame", length_m=frame_axis_length(measured),
                    label="tracker frame (fitted)")
    scene.frame_central(np.vstack([measured, tcp_poses(robot, q_show).position]))
    scene.add_note(f"{d.n_measurements} measurements" + (f" of {d.frames_measured[0]}" if len(d.frames_measured) > 1
                                                        else "")
                   + f"; base frame of the robot; segments magnified x {magnify:g}, the as-built ghost's "
                     f"geometric errors x {ghost:g}")
    return scene

