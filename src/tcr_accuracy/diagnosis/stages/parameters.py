"""Stage 6: the fitted parameters -- every value with its standard error, 95 % interval and
physical range, the parameters held on their fit range's bound, the as-built geometry and the
tracker frame ``trackerMbase``, and how far that geometry moves the tool frame, tilts the axes and
puts the measured point from a given TCP offset, against what the robot's class allows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ...effects import effect_class
from ...frames.rigid import homogeneous
from ...model.errors import ErrorModel
from ..bases import ordered
from ..plausibility import TOLERANCES, geometry_checks, robot_class
from ..uncertainty import joint_function_bands, parameter_table
from .candidates import CandidateSet
from .register import RegisteredMeasurements
from .select import Selection


@dataclass(frozen=True)
class FittedParameters:
    """What stage 6 found (SI units).

    Attributes
    ----------
    values : dict
        effect -> {parameter name: fitted value} (the identifiable parameters).
    units : dict
        effect -> {parameter name: SI unit}.
    full_vectors : dict
        effect -> (k,) every parameter of the effect on the main frame's chain (zeros where not
        identifiable): what rebuilds the fitted model.
    table : dict
        effect -> {"values", "std", "interval", "range", "pinned"} by parameter name.
    as_built_x : ndarray
        The geometric effects' error vector (ErrorModel layout), the base twist taken out.
    trackerMbase : ndarray of shape (4, 4)
        The robot's base in the tracker frame: the closed-form frame with the fitted base twist.
    identifiability : dict
        The final model's identifiability report (JSON form), and the whole vocabulary's.
    joint_function_bands : dict
        effect -> joint -> fitted function of the joint's own angle with its standard error.
    effect_options : dict
        effect -> the options it was fitted with.
    physics : dict
        effect -> why its parameters lie in their range.
    notes : tuple of str
    geometry_checks : tuple of GeometryCheck
        The as-built geometry against what the robot's class allows: axis tilts, the tool frame's
        displacement and rotation, the fitted TCP offset against a given one
        (:mod:`~tcr_accuracy.diagnosis.plausibility`).
    tolerance : GeometryTolerance or None
        The tolerances they were judged against.
    """

    values: dict
    units: dict
    full_vectors: dict
    table: dict
    as_built_x: np.ndarray
    trackerMbase: np.ndarray
    identifiability: dict
    joint_function_bands: dict
    effect_options: dict
    physics: dict
    notes: tuple
    geometry_checks: tuple = ()
    tolerance: object = None


def collect_parameters(registered: RegisteredMeasurements, candidate_set: CandidateSet,
                       selection: Selection, tcp_offset: np.ndarray | None = None) -> FittedParameters:
    """Stage 6 of the diagnosis. ``tcp_offset``: the first measured point's offset from its robot's tool
    frame as the user knows it (3,) [m], checked against the fitted one; None: not checked."""
    engine, bases = candidate_set.engine, candidate_set.bases
    selected = ordered(selection.selected)
    final = engine.evaluate(selected, exact=True)
    notes: list = []
    keep, identifiability = engine.identify(tuple(selected))
    identifiability = {**identifiability, "all_effects": candidate_set.identifiability_all}
    table = parameter_table(final, bases, selected)
    for e, rows in table.items():
        for pinned in rows["pinned"]:
            notes.append(f"{pinned['parameter']} is held at the {pinned['bound']} end of its fit range (what keeps a "
                         f"fit sane, far beyond its physics: {effect_class(e).physics}): the data push further, which "
                         "no mechanism explains")
    theta = final["phi"] * final["scale"]
    values, units, full_vectors = {}, {}, {}
    robot = registered.robot
    em = ErrorModel(robot)
    as_built = np.zeros(em.size)
    offset = 0
    for e in selected:
        b = bases[e]
        union = np.zeros(len(b.names))
        union[keep[e]] = theta[offset:offset + keep[e].size]
        offset += keep[e].size
        values[e] = {b.names[k]: union[k] for k in keep[e]}
        units[e] = {b.names[k]: b.units[k] for k in keep[e]}
        full = union[b.index[0]]  # the main frame's own parameter vector
        full_vectors[e] = full
        if effect_class(e).geometric:
            as_built += b.per_part[0].basis.errors(full, rows=[0])[0]
    base_twist = as_built[em.base_slice].copy()
    as_built[em.base_slice] = 0.0  # the base twist belongs to the tracker frame, not the robot
    tracker = homogeneous(*registered.stations[0]) @ pin.exp6(base_twist).homogeneous
    tolerance = TOLERANCES[robot_class(robot)]
    first = registered.parts[0]
    checks = geometry_checks(robot, registered.measurements.q, as_built, table,
                             "frames.tool" if len(registered.parts) == 1 else f"frames.{first.label}", tcp_offset,
                             tolerance)
    return FittedParameters(
        values=values, units=units, full_vectors=full_vectors, table=table, as_built_x=as_built,
        trackerMbase=tracker, identifiability=identifiability,
        joint_function_bands=joint_function_bands(final, bases, selected, registered.measurements.q),
        effect_options={e: dict(bases[e].per_part[0].effect.options) for e in selected},
        physics={e: effect_class(e).physics for e in table}, notes=tuple(notes), geometry_checks=tuple(checks),
        tolerance=tolerance)
