"""A diagnosis as JSON: the form ``diagnose --json`` writes and :meth:`Diagnosis.from_dict` reads back.

:func:`diagnosis_document` writes a fitted :class:`~tcr_accuracy.diagnosis.result.Diagnosis`
(mm for lengths with ``_mm`` keys, SI for the parameters, plain JSON values: an unbounded side
of a range is null). :data:`STORED_VIEWS` reads each of the diagnosis' views back from such a
document, in SI as the fitted diagnosis gives them; :data:`NOT_STORED` names what the file does
not hold (the per-row arrays: a 1000-row diagnosis would carry 100 kB of residuals per view, and
a report reads none of them), which a diagnosis read from a file refuses with
:class:`~tcr_accuracy.exceptions.NotStoredError`.

The base-to-tracker transform is written under ``trackerMbase`` (``p_tracker = trackerMbase @
p_base``); files written before it was named so hold it under ``tracker_transform``, which
:func:`tcr_accuracy.read_result` reads as the same key.
"""

from __future__ import annotations

import math

import numpy as np

from ..effects import make_effect
from ..frames.noise import NoiseEstimate
from ..frames.uncertainty_budget import PointSet
from ..io.json_values import finite_or, plain
from .records import ErrorStats, Step

#: Key of the base-to-tracker transform in the JSON form, and the key files of 0.1 wrote it under.
TRACKER_KEY, OLD_TRACKER_KEY = "trackerMbase", "tracker_transform"


def diagnosis_document(d) -> dict:
    """The JSON form of a fitted diagnosis ``d`` (plain values, mm keys, parameters in SI)."""
    last = d.steps[-1]
    robot = d.stages.register.robot
    out = {
        "robot": d.robot_name,
        "measurements": d.source,
        "robot_source": robot.robot_source,
        "tool_frame": d.frames_measured[0],
        "joint_names": list(d.joint_names),
        "n_measurements": d.n_measurements,
        "folds": d.folds,
        "fold_assignments": d.fold_assignments,
        "gap": d.gap.to_dict(),
        "where": d.where_mm,
        "identifiability": d.identifiability,
        "candidates": d.candidates,
        "steps": [s.to_dict() for s in d.steps],
        "selected_effects": list(d.selected_effects),
        "primary_effect": d.primary_effect,
        "primary_group": list(d.primary_group),
        "primary_tied": list(d.primary_tied),
        "ambiguous": d.ambiguous,
        "swaps": d.swaps,
        "search": d.search,
        "second_order": d.second_order,
        "leave_one_out": d.leave_one_out,
        "backward_eliminated": d.eliminated,
        "noise_floor_mm": d.noise_floor * 1e3,
        "tracker_noise_mm": d.tracker_noise * 1e3,
        "noise": d.noise.to_dict() if d.noise is not None else None,
        "final_heldout_rms_mm": last.heldout.rms * 1e3,
        "final_over_noise": last.heldout.rms / d.noise_floor if d.noise_floor > 0 else None,
        "extra_scatter": d.scatter,
        "structure_remains": d.structure_remains,
        "structure_verdict": d.structure.get("verdict"),
        "structure": d.structure,
        "parameters": {e: {k: float(v) for k, v in p.items()} for e, p in d.parameters.items()},
        "parameter_std": {e: dict(t["std"]) for e, t in d.parameter_table.items()},
        "parameter_interval_95": {e: dict(t["interval"]) for e, t in d.parameter_table.items()},
        "parameter_units": d.parameter_units,
        "physical": {e: {"plausible": bool(getattr(d.stages.attribute.mechanism_of(e), "physical", True)),
                         "range": dict(t["range"]), "fit_range": dict(t["fit_range"]),
                         "pinned": list(t["pinned"]), "reason": d.physics.get(e, "")}
                     for e, t in d.parameter_table.items()},
        "outside_physics": list(d.outside_physics),
        "mechanisms": d.mechanisms,
        "families": d.families,
        "primary_family": d.primary_family,
        "own_share_ranking": d.own_share_ranking,
        "interval_method": d.interval_method,
        "plausibility": {"tolerance": d.geometry_tolerance, "checks": d.geometry_checks},
        "confounding": d.confounding,
        "instrument": d.instrument,
        "sessions": list(d.sessions),
        "session_setup": d.session_setup,
        "drift": list(d.drift),
        "effect_options": d.effect_options,
        "joint_functions": d.joint_function_bands,
        "selection_frequency": dict(d.selection.get("frequency", {})),
        "selection": {k: v for k, v in d.selection.items() if k != "frequency"},
        TRACKER_KEY: d.trackerMbase,
        "notes": list(d.notes),
        "n_fits": d.n_fits,
        "contribution_mm": {e: v * 1e3 for e, v in d.contribution.items()},
        # every effect's full parameter vector by name [SI] on the first measured frame's chain: what
        # rebuilds the fitted model (export); the identifiable ones are `parameters`' values, the others 0
        "effect_parameters": {e: dict(zip(make_effect(e, robot, **d.effect_options.get(e, {})).parameter_names(),
                                          (float(v) for v in vector)))
                              for e, vector in d.effect_parameters.items()},
        "effect_parameters_units": "SI (m, rad, rad/Nm, m/N, 1/K)",
    }
    if robot.kinematics:  # the nominal robot is the robot's own (factory) kinematics, not its URDF's
        out["kinematics"] = robot.kinematics
    position = np.asarray(d.stages.register.measurements.position, dtype=float)
    # the measured points' moments and box in the tracker frame: what the report's uncertainty budget needs
    out["measured_points"] = PointSet.of(position[np.isfinite(position).all(axis=1)]).to_dict()
    if out["robot_source"] is None:  # a robot built from URDF text or perturbed: no source to load it from
        del out["robot_source"]
    if len(d.frames_measured) > 1:
        out["frames_measured"] = list(d.frames_measured)
        out["heldout_by_frame"] = {f: s.to_dict() for f, s in d.heldout_by_frame.items()}
    if d.orientation:
        out["orientation"] = d.orientation
    return plain(out)


# ---------------------------------------------------------------------------------------
# Reading the views back
# ---------------------------------------------------------------------------------------
def _stats(doc: dict) -> ErrorStats:
    return ErrorStats(doc["mean_mm"] * 1e-3, doc["rms_mm"] * 1e-3, doc["max_mm"] * 1e-3, int(doc["count"]))


def _step(doc: dict, count: int) -> Step:
    gain = None
    if doc.get("gain_heldout_rms_mm") is not None and doc.get("gain_interval_mm") is not None:
        low, high = doc["gain_interval_mm"]
        gain = (doc["gain_heldout_rms_mm"] * 1e-3, finite_or(low, -math.inf) * 1e-3, finite_or(high, math.inf) * 1e-3)
    heldout = ErrorStats(doc["heldout_mean_mm"] * 1e-3, doc["heldout_rms_mm"] * 1e-3, doc["heldout_max_mm"] * 1e-3,
                         int(doc.get("heldout_count", count)))
    return Step(doc["effect"], tuple(doc.get("effects", ())), int(doc["n_parameters"]), doc["train_rms_mm"] * 1e-3,
                heldout, doc.get("z_vs_previous"), gain)


def _pair(bounds) -> list:
    return [finite_or(bounds[0], -math.inf), finite_or(bounds[1], math.inf)]


def _parameter_table(doc: dict) -> dict:
    out = {}
    for e, values in doc["parameters"].items():
        physical = (doc.get("physical") or {}).get(e, {})
        std = doc["parameter_std"].get(e, {})
        interval = (doc.get("parameter_interval_95") or {}).get(e, {})
        out[e] = {"values": dict(values),
                  "std": {n: finite_or(std.get(n), math.inf) for n in values},
                  "interval": {n: _pair(interval.get(n, (None, None))) for n in values},
                  "range": {n: _pair(b) for n, b in physical.get("range", {}).items()},
                  "fit_range": {n: _pair(b) for n, b in physical.get("fit_range", {}).items()},
                  "pinned": [dict(p) for p in physical.get("pinned", [])]}
    return out


def _noise(doc: dict):
    noise = doc.get("noise")
    if noise is None:
        return None
    per_axis = noise.get("per_axis_mm", doc["tracker_noise_mm"])
    return NoiseEstimate(per_axis * 1e-3, noise.get("source", ""), bool(noise.get("independent", False)),
                         noise.get("detail", ""))


def _tracker(doc: dict) -> np.ndarray:
    return np.array(doc[TRACKER_KEY] if TRACKER_KEY in doc else doc[OLD_TRACKER_KEY], dtype=float)


def _outside_physics(doc: dict) -> list:
    if "outside_physics" in doc:
        return list(doc["outside_physics"])
    raise KeyError("outside_physics")


def _frames_measured(doc: dict) -> list:
    if "frames_measured" in doc:
        return list(doc["frames_measured"])
    return [doc["tool_frame"]]


def _joint_names(doc: dict) -> list:
    if "joint_names" in doc:
        return list(doc["joint_names"])
    return list(doc["where"]["joints"])  # files before the key: every joint of the chain has its line there


#: Each view of a diagnosis, read from its JSON form (SI, as the fitted diagnosis gives it).
STORED_VIEWS = {
    "gap": lambda doc: _stats(doc["gap"]),
    "where_mm": lambda doc: doc["where"],
    "identifiability": lambda doc: doc["identifiability"],
    "candidates": lambda doc: doc["candidates"],
    "steps": lambda doc: [_step(s, int(doc["gap"]["count"])) for s in doc["steps"]],
    "selected_effects": lambda doc: list(doc["selected_effects"]),
    "primary_effect": lambda doc: doc["primary_effect"],
    "primary_group": lambda doc: list(doc["primary_group"]),
    "primary_tied": lambda doc: list(doc["primary_tied"]),
    "leave_one_out": lambda doc: list(doc["leave_one_out"]),
    "eliminated": lambda doc: list(doc["backward_eliminated"]),
    "swaps": lambda doc: list(doc["swaps"]),
    "search": lambda doc: dict(doc["search"]),
    "ambiguous": lambda doc: list(doc["ambiguous"]),
    "noise": _noise,
    "noise_floor": lambda doc: doc["noise_floor_mm"] * 1e-3,
    "tracker_noise": lambda doc: doc["tracker_noise_mm"] * 1e-3,
    "scatter": lambda doc: doc["extra_scatter"],
    "structure": lambda doc: doc["structure"],
    "parameters": lambda doc: {e: dict(v) for e, v in doc["parameters"].items()},
    "parameter_units": lambda doc: {e: dict(v) for e, v in doc["parameter_units"].items()},
    "parameter_table": _parameter_table,
    "effect_parameters": lambda doc: {e: np.array(list(v.values()), dtype=float)
                                      for e, v in doc["effect_parameters"].items()},
    "effect_parameter_names": lambda doc: {e: list(v) for e, v in doc["effect_parameters"].items()},
    "effect_options": lambda doc: {e: dict(o or {}) for e, o in doc["effect_options"].items()},
    "physics": lambda doc: {e: p.get("reason", "") for e, p in doc["physical"].items()},
    "joint_function_bands": lambda doc: {e: {j: {k: np.asarray(v, dtype=float) for k, v in band.items()}
                                             for j, band in joints.items()}
                                         for e, joints in doc["joint_functions"].items()},
    "trackerMbase": _tracker,
    "frames_measured": _frames_measured,
    "heldout_by_frame": lambda doc: {f: _stats(s) for f, s in (doc.get("heldout_by_frame") or {}).items()},
    "orientation": lambda doc: dict(doc.get("orientation") or {}),
    "sessions": lambda doc: list(doc["sessions"]),
    "session_setup": lambda doc: doc.get("session_setup"),  # None: one session, or a file of before 0.1.x
    "drift": lambda doc: list(doc["drift"]),
    "selection": lambda doc: {**doc["selection"], "frequency": dict(doc["selection_frequency"])},
    "mechanisms": lambda doc: list(doc["mechanisms"]),
    "families": lambda doc: list(doc["families"]),
    "primary_family": lambda doc: doc["primary_family"],
    "outside_physics": _outside_physics,
    "confounding": lambda doc: list(doc["confounding"]),
    "instrument": lambda doc: doc["instrument"],
    "contribution": lambda doc: {e: v * 1e-3 for e, v in doc["contribution_mm"].items()},
    "second_order": lambda doc: doc["second_order"],
    "own_share_ranking": lambda doc: list(doc["own_share_ranking"]),
    "interval_method": lambda doc: doc["interval_method"],
    "geometry_checks": lambda doc: list(doc["plausibility"]["checks"]),
    "geometry_tolerance": lambda doc: doc["plausibility"]["tolerance"],
    "measured_points": lambda doc: doc["measured_points"],
    "notes": lambda doc: list(doc["notes"]),
    "fold_assignments": lambda doc: doc["fold_assignments"],
    "joint_names": _joint_names,
}

#: What a diagnosis read from its JSON form does not hold, and what each is.
NOT_STORED = {
    "stages": "the stages' own results",
    "final_residual": "the (N, 3) in-sample residual of each row",
    "heldout_residual": "the (N, 3) held-out residual of each row",
    "gap_residual": "the (N, 3) residual of each row after the frames alone",
    "semivariograms": "the residual's semivariograms",
    "q": "the rows' joint values",
    "nominal_position": "the rows' nominal TCP positions",
    "gravity_torque": "the rows' gravity torques",
    "as_built_x": "the geometric error vector (AsBuiltModel.from_diagnosis rebuilds the model from "
                  "effect_parameters)",
    "registration": "the first session's closed-form tracker frame (trackerMbase holds the fitted one)",
}
