"""What the fitted model attributes to each effect, and where its first-order effect models end.

* :func:`contributions` -- the TCP motion each chosen effect's fitted parameters cause,
  beyond what a rigid frame change could absorb.
* :func:`tied_own_shares` -- the chosen effects whose own share the data cannot rank below
  the largest: the primary effect is then one of them, not the largest by a hair.
* :func:`fixed_point_check` -- the effects are first order in their own joint deflections
  (compliance takes gravity at the commanded pose): how far one fixed-point step would move
  the TCP, against the noise floor.

Lengths in m inside; the returned dicts carry mm in ``_mm`` keys.
"""

from __future__ import annotations

import numpy as np

from ..effects.compose import fixed_point_motion
from .bases import ordered
from .paired import entry_z
from ..model.errors import ErrorModel
from ..model.kinematics import tcp_poses


def contributions(part, bases, chosen, full_parameters, nominal) -> dict:
    """How much of the gap each chosen effect accounts for: the TCP motion its fitted
    parameters cause, after taking out what a rigid frame change could absorb."""
    frames_g = bases["frames"].per_part[0].g[:, :3]
    frames_cols = frames_g.reshape(-1, frames_g.shape[2])
    em = ErrorModel(part.robot)
    contribution = {}
    for e in chosen:
        x_e = bases[e].per_part[0].basis.errors(full_parameters[e])
        motion = (tcp_poses(part.robot, part.q, x_e, em).position - nominal).ravel()
        rigid = frames_cols @ np.linalg.lstsq(frames_cols, motion, rcond=None)[0]
        contribution[e] = float(np.sqrt(np.mean((motion - rigid) ** 2) * 3))
    return contribution


def fixed_point_check(part, bases, full_parameters, noise_floor) -> tuple[float, float, str | None]:
    """The fitted model is first order in its joint deflections (gravity at the commanded
    pose): how much one fixed-point step (gravity at the deflected pose) would move the TCP
    [m], RMS and max, and a note when the RMS is more than a quarter of the noise floor [m]."""
    effects = [bases[e].per_part[0].effect for e in full_parameters]  # with the options they were fitted with
    motion = fixed_point_motion(part.robot, effects, list(full_parameters.values()), part.q, part.context)
    rms = float(np.sqrt(np.mean(np.sum(motion**2, axis=1))))
    largest = float(np.max(np.linalg.norm(motion, axis=1)))
    note = None
    if not rms <= 0.25 * noise_floor:
        note = (f"the fitted joint deflections are large enough that first order is not enough: evaluated at "
                f"the deflected joints (gravity where the arm sags to, gear errors where the joint really is) "
                f"they move the TCP by {rms * 1e3:.4g} mm RMS more, {rms / noise_floor:.2g} x the noise floor; "
                "what is left, and any effect chosen late for it, may partly be that")
    return rms, largest, note


def tied_own_shares(engine, model: list, leave_one_out: list, selection_z: float) -> list:
    """Of the effects in ``leave_one_out`` (rows of the final ``model`` without each), the one with
    the largest own share (held-out error without it, the others held to their own parameters)
    and every other whose own share it does not beat on the same held-out rows by the selection's
    test (:func:`~.paired.entry_z` of ``selection_z``): a geometry error and a compliance error that each leave 2 mm are not
    ranked by 0.01 mm between them."""
    if not leave_one_out:
        return []
    ranked = sorted(leave_one_out, key=lambda row: -row["own_share_increase_mm"])
    keep = engine.kept(tuple(ordered(model)))

    def without(effect):  # the leave-one-out fit of its own share (cached by the engine)
        rest = ordered([s for s in model if s != effect])
        return engine.evaluate(rest, keep={s: keep[s] for s in rest})["heldout_squares"]

    top = ranked[0]["dropped"]
    return [top] + [row["dropped"] for row in ranked[1:]
                    if entry_z(without(top), without(row["dropped"])) < selection_z]
