"""A result file's figures against each other, and each number written once.

A schema says what type and range each key has; it cannot say that a held-out max below its own
RMS is a forgery (the RMS of a set of numbers lies between their mean and their max), that an
AP_P is the norm of its x, y, z components, or that the two copies of a fitted parameter (the
report's ``parameters``, the export's ``effect_parameters``) say the same. :func:`check_consistency`
says it, for every kind of result, before anything uses the file: one
:class:`~tcr_accuracy.exceptions.InputError` line naming the file and the key.

:func:`check_robot` holds a result to the robot its ``robot_source`` loads (its name, its joints'
names and kinds, the joint values it was measured at against the robot's travel), and
:func:`check_fitted_to` a diagnosis to the measurements given with it (another robot's, or
another campaign's, with the right row count: the fitted model misses them by far more than the
diagnosis' own in-sample figure).
"""

from __future__ import annotations

import math

from ..exceptions import InputError

#: Relative slack of a comparison of two figures: a JSON number holds 17 significant digits, the
#: mm conversion rounds in the 16th.
ROUNDING = 1e-9
#: A held-out RMS below this fraction of the noise floor is implausible: the held-out errors hold
#: the noise of the held-out points themselves (RMS norm: the noise floor). A quarter leaves room
#: for a noise floor overstated four times (an instrument's MPE taken for its noise).
NOISE_FRACTION = 0.25
#: The fitted model misses the measurements given with a diagnosis by at most this many times its
#: own in-sample RMS (plus a noise floor) when they are the measurements it was fitted to; each form's
#: frame is fitted again on them (Kabsch), which can only lower it.
FITTED_TO_FACTOR = 3.0


def _close(a: float, b: float, relative: float = ROUNDING) -> bool:
    return abs(a - b) <= relative * max(abs(a), abs(b)) + 1e-12


def _number(value) -> bool:
    """A JSON number (not a boolean): the parts of a result the schema does not type are checked only
    where they hold numbers."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _figures(block, where: str, source, keys=("mean_mm", "rms_mm", "max_mm")) -> None:
    """mean <= RMS <= max in one block of figures (the RMS of non-negative numbers lies between
    their mean and their max), where the block has them."""
    if not isinstance(block, dict):
        return
    values = [block.get(k) for k in keys]
    for (low_key, low), (high_key, high) in zip(zip(keys, values), list(zip(keys, values))[1:]):
        if _number(low) and _number(high) and low > high * (1 + ROUNDING) + 1e-12:
            raise InputError(f"{source}: {where}: {low_key} {low:g} is above {high_key} {high:g}: the RMS of a set "
                             "of errors lies between their mean and their max; figures that contradict each other")


def check_consistency(doc: dict, kind: str, source) -> None:
    """The figures of a result of ``kind`` against each other, and its copies of one number against
    each other; InputError naming ``source`` and the key at fault."""
    {"diagnosis": _diagnosis, "iso9283": _iso, "comparison": _comparison,
     "export": _export}.get(kind, lambda d, s: None)(doc, source)


# ---------------------------------------------------------------------------------------
# A diagnosis
# ---------------------------------------------------------------------------------------
def _diagnosis(doc: dict, source) -> None:
    _figures(doc.get("gap"), "$.gap", source)
    steps = doc.get("steps") or []
    for i, step in enumerate(steps):
        _figures(step, f"$.steps[{i}]", source, ("heldout_mean_mm", "heldout_rms_mm", "heldout_max_mm"))
    for i, row in enumerate(doc.get("leave_one_out") or []):
        _figures(row, f"$.leave_one_out[{i}]", source, ("heldout_mean_mm", "heldout_rms_mm", "heldout_max_mm"))
    for frame, block in (doc.get("heldout_by_frame") or {}).items():
        _figures(block, f"$.heldout_by_frame[{frame!r}]", source)
    sessions = doc.get("sessions") or []
    for i, session in enumerate(sessions):
        if isinstance(session, dict):
            for part in ("gap", "heldout"):
                _figures(session.get(part), f"$.sessions[{i}].{part}", source)
    _diagnosis_copies(doc, steps, sessions, source)
    _noise_floor(doc, steps, source)
    _one_copy_of_each_parameter(doc, source)
    _intervals_hold_their_values(doc, source)


def _diagnosis_copies(doc: dict, steps: list, sessions: list, source) -> None:
    """The figures a diagnosis writes twice, or that count what its lists hold."""
    if steps and "final_heldout_rms_mm" in doc and not _close(doc["final_heldout_rms_mm"], steps[-1]["heldout_rms_mm"]):
        raise InputError(f"{source}: $.final_heldout_rms_mm: {doc['final_heldout_rms_mm']:g} mm, but the last step's "
                         f"held-out RMS is {steps[-1]['heldout_rms_mm']:g} mm: one figure, written twice, must agree")
    ratio = doc.get("final_over_noise")
    if steps and ratio is not None and doc.get("noise_floor_mm") and \
            not _close(ratio, steps[-1]["heldout_rms_mm"] / doc["noise_floor_mm"], 1e-6):
        raise InputError(f"{source}: $.final_over_noise: {ratio:g} is not the final held-out RMS over the noise floor "
                         f"({steps[-1]['heldout_rms_mm'] / doc['noise_floor_mm']:g})")
    per_axis = doc.get("tracker_noise_mm")
    if per_axis is not None and doc.get("noise_floor_mm") is not None and \
            not _close(doc["noise_floor_mm"], math.sqrt(3) * per_axis, 1e-6):
        raise InputError(f"{source}: $.noise_floor_mm: {doc['noise_floor_mm']:g} mm is not sqrt(3) x the per-axis "
                         f"noise $.tracker_noise_mm {per_axis:g} mm")
    noise = doc.get("noise") or {}
    if per_axis is not None and noise.get("per_axis_mm") is not None and not _close(noise["per_axis_mm"], per_axis):
        raise InputError(f"{source}: $.noise.per_axis_mm: {noise['per_axis_mm']:g} mm, but $.tracker_noise_mm says "
                         f"{per_axis:g} mm: one figure, written twice, must agree")
    selected = doc.get("selected_effects")
    if steps and selected is not None and "effects" in steps[-1] and set(steps[-1]["effects"]) != set(selected):
        raise InputError(f"{source}: $.selected_effects: {', '.join(selected)}, but the last step's model is "
                         f"{', '.join(steps[-1]['effects'])}")
    if selected is not None and doc.get("primary_effect") not in (None, *selected):
        raise InputError(f"{source}: $.primary_effect: {doc['primary_effect']!r} is not a selected effect")
    n_fitted = sum(len(v) for v in (doc.get("parameters") or {}).values())
    if steps and set(doc.get("parameters") or {}) == set(steps[-1].get("effects", doc.get("parameters") or {})) \
            and steps[-1]["n_parameters"] != n_fitted:
        raise InputError(f"{source}: $.steps[{len(steps) - 1}].n_parameters: {steps[-1]['n_parameters']}, but "
                         f"$.parameters holds {n_fitted}: a count that does not match its list")
    n, gap = doc.get("n_measurements"), doc.get("gap") or {}
    frames = len(doc.get("frames_measured") or [None])
    if n is not None and gap.get("count") is not None and gap["count"] != n * frames:
        raise InputError(f"{source}: $.gap.count: {gap['count']}, but {n} measurements of {frames} measured "
                         f"frame(s) are {n * frames} points")
    rows = [s.get("n_measurements") for s in sessions if isinstance(s, dict)]
    if n is not None and rows and all(_number(r) for r in rows) and sum(rows) != n:
        raise InputError(f"{source}: $.sessions: {sum(rows)} rows over the sessions, but $.n_measurements is {n}")


def _noise_floor(doc: dict, steps: list, source) -> None:
    """Every held-out RMS at least :data:`NOISE_FRACTION` of the noise floor."""
    floor = doc.get("noise_floor_mm")
    if not floor:
        return
    for i, step in enumerate(steps):
        if step["heldout_rms_mm"] < NOISE_FRACTION * floor:
            raise InputError(f"{source}: $.steps[{i}].heldout_rms_mm: {step['heldout_rms_mm']:g} mm is below "
                             f"{NOISE_FRACTION:g} x the noise floor {floor:g} mm: held-out errors hold the held-out "
                             "points' own noise, whose RMS is the noise floor; figures that contradict each other")


def _one_copy_of_each_parameter(doc: dict, source) -> None:
    """``effect_parameters`` (every effect's full vector, what export reads) and ``parameters`` (the
    identifiable ones, what report and compare read) are one fit: each parameter in both has one
    value, the others are 0 (not identifiable, so not fitted; with several measured frames, whose
    parameters are named per frame in ``parameters``, the others are not compared)."""
    full, fitted = doc.get("effect_parameters"), doc.get("parameters") or {}
    if not isinstance(full, dict):
        return
    if set(full) != set(fitted):
        extra = sorted(set(full) ^ set(fitted))
        raise InputError(f"{source}: $.effect_parameters: effect {extra[0]} is in one of effect_parameters and "
                         "parameters only; they are one fit, written twice")
    several = len(doc.get("frames_measured") or []) > 1  # `parameters` names each frame's own; `effect_parameters`
    for effect, values in full.items():                  # the first chain's, under the effect's names
        mine = fitted[effect]
        for name, value in values.items():
            if several and name not in mine:
                continue
            other = mine.get(name, 0.0)
            if not _close(value, other, 1e-12):
                said = f"{other:.10g}" if name in mine else "0 (not identifiable, not fitted)"
                raise InputError(f"{source}: $.effect_parameters.{effect}['{name}']: {value:.10g}, but "
                                 f"$.parameters.{effect}['{name}'] says {said}: one fitted value, written twice, must "
                                 "agree (export reads one copy, report and compare the other)")


def _intervals_hold_their_values(doc: dict, source) -> None:
    """Each parameter's 95 % interval holds its value (null: unbounded on that side)."""
    for effect, values in (doc.get("parameters") or {}).items():
        intervals = (doc.get("parameter_interval_95") or {}).get(effect) or {}
        for name, value in values.items():
            low, high = intervals.get(name, (None, None))
            slack = ROUNDING * abs(value) + 1e-15
            if (low is not None and value < low - slack) or (high is not None and value > high + slack):
                raise InputError(f"{source}: $.parameter_interval_95.{effect}['{name}']: [{low}, {high}] does "
                                 f"not hold the value {value:g}: an interval holds its estimate")


# ---------------------------------------------------------------------------------------
# An ISO 9283 evaluation
# ---------------------------------------------------------------------------------------
def _iso(doc: dict, source, where: str = "$") -> None:
    poses = doc.get("poses") or []
    for i, pose in enumerate(poses):
        components = [pose.get(f"ap_{a}_mm") for a in "xyz"]
        if None in components or pose.get("ap_mm") is None:
            continue
        norm = math.sqrt(sum(c * c for c in components))
        if not _close(pose["ap_mm"], norm, 1e-6) and abs(pose["ap_mm"] - norm) > 1e-9:
            raise InputError(f"{source}: {where}.poses[{i}].ap_mm: {pose['ap_mm']:g} mm, but AP_P is the norm of "
                             f"its components AP_x, AP_y, AP_z ({norm:g} mm): figures that contradict each other")
    summary = doc.get("summary") or {}
    aps = [p["ap_mm"] for p in poses if p.get("ap_mm") is not None]
    if aps and summary.get("ap_max_mm") is not None and not _close(summary["ap_max_mm"], max(aps)):
        raise InputError(f"{source}: {where}.summary.ap_max_mm: {summary['ap_max_mm']:g} mm, but the poses' largest "
                         f"AP_P is {max(aps):g} mm")
    if aps and summary.get("ap_mean_mm") is not None and not _close(summary["ap_mean_mm"], sum(aps) / len(aps), 1e-6):
        raise InputError(f"{source}: {where}.summary.ap_mean_mm: {summary['ap_mean_mm']:g} mm, but the poses' mean "
                         f"AP_P is {sum(aps) / len(aps):g} mm")
    rps = [p["rp_mm"] for p in poses if p.get("rp_mm") is not None]
    said = summary.get("rp_max_mm")
    if (said is None) != (not rps) or (rps and not _close(said, max(rps))):
        raise InputError(f"{source}: {where}.summary.rp_max_mm: {said}, but the poses' largest RP_l is "
                         f"{max(rps) if rps else None}")
    visits = sum(p.get("n", 0) for p in poses)
    if doc.get("n_visits") and visits != doc["n_visits"]:
        raise InputError(f"{source}: {where}.n_visits: {doc['n_visits']}, but the poses count {visits} visits")
    if doc.get("n_readings") and doc.get("n_visits") and doc["n_visits"] > doc["n_readings"]:
        raise InputError(f"{source}: {where}.n_visits: {doc['n_visits']} visits of {doc['n_readings']} readings")
    if isinstance(doc.get("compensated"), dict):
        _iso(doc["compensated"], source, f"{where}.compensated")
    for i, block in enumerate(doc.get("conditions") or []):
        _iso(block, source, f"{where}.conditions[{i}]")


# ---------------------------------------------------------------------------------------
# A comparison
# ---------------------------------------------------------------------------------------
def _comparison(doc: dict, source) -> None:
    tcp = doc.get("tcp_effect") or {}
    for key in ("all_changes", "significant_changes"):
        _figures(tcp.get(key), f"$.tcp_effect.{key}", source)
    threshold = doc["z_threshold"]
    for key in ("changes", "setup_changes"):
        for i, c in enumerate(doc.get(key) or []):
            where = f"$.{key}[{i}]"
            if not _close(c["change"], c["new"] - c["old"], 1e-9) and abs(c["change"] - (c["new"] - c["old"])) > 1e-15:
                raise InputError(f"{source}: {where}.change: {c['change']:g}, but new - old is {c['new'] - c['old']:g}")
            if c["std_error"] and c["z"] is not None and \
                    not _close(c["z"], abs(c["new"] - c["old"]) / c["std_error"], 1e-6):
                raise InputError(f"{source}: {where}.z: {c['z']:g}, but |change| / std_error is "
                                 f"{abs(c['new'] - c['old']) / c['std_error']:g}")
            z = c["z"] if c["z"] is not None else (math.inf if c["std_error"] == 0 and c["change"] else 0.0)
            if bool(c["significant"]) != (z > threshold):
                raise InputError(f"{source}: {where}.significant: {c['significant']}, but z = {z:g} against the "
                                 f"threshold {threshold:g}")
    named = [c["parameter"] for c in doc.get("changes") or [] if c["significant"]]
    if "significant" in doc and sorted(doc["significant"]) != sorted(named):
        raise InputError(f"{source}: $.significant: {', '.join(doc['significant']) or 'none'}, but the changes "
                         f"flagged significant are {', '.join(named) or 'none'}")


def _export(doc: dict, source) -> None:
    """Each delivered form's figures (export's accuracy.json): mean <= RMS <= max, the points they are
    on as many as the point set of those poses holds."""
    sets = doc.get("point_sets") or {}
    for i, record in enumerate(doc.get("accuracy") or []):
        _figures(record, f"$.accuracy[{i}]", source)
        points = sets.get(record.get("on")) or {}
        if record.get("on") != "k-fold held-out" and _number(points.get("n")) and record.get("n") != points["n"]:
            raise InputError(f"{source}: $.accuracy[{i}].n: {record.get('n')} {record.get('on')} poses, but "
                             f"$.point_sets.{record.get('on')} holds {points['n']}: a count that does not match")


# ---------------------------------------------------------------------------------------
# Against the robot, and against the measurements given with it
# ---------------------------------------------------------------------------------------
#: A measured joint value may lie beyond the robot's travel by this share of the travel (joint limits
#: written a little tight in a URDF; the measurements outside are warned about, not refused).
TRAVEL_SLACK = 0.05


def check_robot(doc: dict, robot, source) -> None:
    """A result of ``robot``: its name, and for a diagnosis its joints (names, kinds) and the joint
    values it was measured at within the robot's travel; InputError naming the key otherwise."""
    import numpy as np

    loaded = f" (what {doc['robot_source']!r} loads)" if "robot_source" in doc else ""
    if doc.get("robot") != robot.name:
        raise InputError(f"{source}: $.robot: {doc.get('robot')!r}, but the robot is {robot.name!r}{loaded}: a result "
                         "of one robot named as another's")
    names = doc.get("joint_names")
    joints = (doc.get("where") or {}).get("joints") or {}
    given = list(names) if names is not None else list(joints)
    if given and given != list(robot.joint_names):
        raise InputError(f"{source}: $.joint_names: {', '.join(given[:8])}, but {robot.name}{loaded} has "
                         f"{', '.join(robot.joint_names[:8])}")
    kinds = dict(zip(robot.joint_names, robot.joint_kinds))
    lower, upper = np.asarray(robot.lower_limits, float), np.asarray(robot.upper_limits, float)
    for k, name in enumerate(robot.joint_names):
        info = joints.get(name)
        if not isinstance(info, dict):
            continue
        unit = "m" if kinds[name] == "prismatic" else "rad"
        if info.get("unit") not in (None, unit):
            raise InputError(f"{source}: $.where.joints.{name}.unit: {info['unit']!r}, but {name} of {robot.name} is "
                             f"{kinds[name]} ({unit})")
        bins = [b for b in info.get("bins") or [] if isinstance(b, dict) and _number(b.get("low"))
                and _number(b.get("high"))]
        if not bins or not (np.isfinite(lower[k]) and np.isfinite(upper[k])):
            continue
        low, high = min(b["low"] for b in bins), max(b["high"] for b in bins)
        slack = TRAVEL_SLACK * (upper[k] - lower[k])
        if low < lower[k] - slack or high > upper[k] + slack:
            raise InputError(f"{source}: $.where.joints.{name}: measured from {low:.4g} to {high:.4g} {unit}, beyond "
                             f"{robot.name}'s travel [{lower[k]:.4g}, {upper[k]:.4g}] {unit}: a diagnosis of another "
                             "robot")


def check_fitted_to(doc: dict, in_sample_rms: float, measurements: str, source) -> None:
    """The measurements given with a diagnosis are those it was fitted to: its full model's RMS on
    them (each session's frame fitted again) ``in_sample_rms`` [m] at most :data:`FITTED_TO_FACTOR`
    times its own in-sample RMS plus a noise floor; InputError naming both otherwise."""
    steps = doc.get("steps") or []
    if not steps:
        return
    own = steps[-1]["train_rms_mm"] * 1e-3
    floor = (doc.get("noise_floor_mm") or 0.0) * 1e-3
    if in_sample_rms > FITTED_TO_FACTOR * own + floor:
        raise InputError(f"{measurements}: the model of {source} misses these measurements by {in_sample_rms * 1e3:.4g} "
                         f"mm RMS, where it was fitted to {own * 1e3:.4g} mm: not the measurements it was fitted to "
                         "(another robot's or another campaign's)")
