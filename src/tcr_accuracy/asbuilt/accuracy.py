"""What each form of a calibration reaches on measured positions.

Every form (the full model, the URDF, a DH table, the UR calibration file, the nominal robot)
is a forward kinematics of the measured point in the robot's base frame. Measured positions are
in the tracker's frame: each form gets **its own** tracker frame, a rigid fit (Kabsch,
:func:`~tcr_accuracy.frames.rigid.rigid_fit`) of its points to the measured ones, one per
session. Its errors are then

* on the measured poses: in-sample, the data the model was fitted to;
* on held-out poses (a check set measured in the frame of the first session): the frame fitted
  on the measured poses, never on the held-out ones, so the figure is what the form predicts.

The full model takes each measured row at its own context (its time in the campaign included);
held-out rows are at the campaign's end (:meth:`~tcr_accuracy.asbuilt.model.AsBuiltModel.state_context`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..exceptions import InputError
from ..frames.rigid import rigid_fit
from ..model.context import MeasurementContext


@dataclass(frozen=True)
class MeasuredPoses:
    """Measured positions of the measured point.

    q : (N, n_joints) [rad, m]; position : (N, 3) in the tracker frame [m]
    context : MeasurementContext of the rows
    session : (N,) int, each row's session (its own tracker frame)
    label : what the rows are (file names), for the figures' captions
    """

    q: np.ndarray
    position: np.ndarray
    context: MeasurementContext
    session: np.ndarray
    label: str

    @classmethod
    def of(cls, measurements, label: str) -> "MeasuredPoses":
        """From a :class:`~tcr_accuracy.io.measurements.MeasurementSet` (its sessions kept)."""
        session = measurements.context.session
        session = np.zeros(len(measurements.q), dtype=int) if session is None else np.asarray(session, dtype=int)
        return cls(np.asarray(measurements.q, dtype=float), np.asarray(measurements.position, dtype=float),
                   measurements.context, session, label)


@dataclass(frozen=True)
class FormAccuracy:
    """The TCP position error of one form on one data set [m].

    form : e.g. "URDF alone"; file : the file that carries it ("" for none)
    on : "measured" (in-sample), "held-out" or "k-fold held-out"; data : the data's label; n : rows
    mean, rms, max : [m]
    frame_rms : RMS [m] of the form's tracker-frame fit on the measured poses (its residual there),
        None where the frame was fitted with the model (k-fold)
    """

    form: str
    file: str
    on: str
    data: str
    n: int
    mean: float
    rms: float
    max: float
    frame_rms: float | None = None

    def to_dict(self) -> dict:
        """JSON-ready, lengths in mm."""
        return {"form": self.form, "file": self.file, "on": self.on, "data": self.data, "n": self.n,
                "mean_mm": self.mean * 1e3, "rms_mm": self.rms * 1e3, "max_mm": self.max * 1e3,
                "frame_rms_mm": None if self.frame_rms is None else self.frame_rms * 1e3}

    @classmethod
    def from_dict(cls, doc: dict) -> "FormAccuracy":
        """From :meth:`to_dict`'s dict (mm)."""
        frame = doc.get("frame_rms_mm")
        return cls(doc["form"], doc["file"], doc["on"], doc["data"], int(doc["n"]), doc["mean_mm"] * 1e-3,
                   doc["rms_mm"] * 1e-3, doc["max_mm"] * 1e-3, None if frame is None else frame * 1e-3)


#: A form's forward kinematics: (q (N, n_joints), context or None, held_out) -> (N, 3) base frame [m].
Kinematics = Callable[[np.ndarray, MeasurementContext, bool], np.ndarray]


def form_accuracy(form: str, file: str, kinematics: Kinematics, measured: MeasuredPoses,
                  held_out: MeasuredPoses | None = None) -> list[FormAccuracy]:
    """The form's errors on the measured poses and, given, on held-out ones.

    Parameters
    ----------
    form, file : names for the result
    kinematics : callable (q, context, held_out) -> (N, 3) base-frame positions [m]
    measured : MeasuredPoses
        Where each session's tracker frame is fitted (and the in-sample figure).
    held_out : MeasuredPoses, optional
        Poses the model was not fitted to, in the first session's tracker frame.

    Returns
    -------
    list of FormAccuracy (measured, then held-out)
    """
    model_points = kinematics(measured.q, measured.context, False)
    registered = np.empty_like(model_points)
    frames = {}
    for s in np.unique(measured.session):
        rows = np.flatnonzero(measured.session == s)
        if rows.size < 3:
            raise InputError(f"{measured.label}: session {s} has {rows.size} rows; a tracker frame needs 3")
        rotation, translation = rigid_fit(model_points[rows], measured.position[rows])
        frames[int(s)] = (rotation, translation)
        registered[rows] = model_points[rows] @ rotation.T + translation
    in_sample = np.linalg.norm(registered - measured.position, axis=1)
    frame_rms = float(np.sqrt(np.mean(in_sample ** 2)))
    out = [error_statistics(form, file, "measured", measured.label, in_sample, frame_rms)]
    if held_out is not None:
        rotation, translation = frames[min(frames)]
        points = kinematics(held_out.q, held_out.context, True) @ rotation.T + translation
        out.append(error_statistics(form, file, "held-out", held_out.label,
                                    np.linalg.norm(points - held_out.position, axis=1), frame_rms))
    return out


def error_statistics(form: str, file: str, on: str, data: str, error: np.ndarray,
                     frame_rms: float | None = None) -> FormAccuracy:
    """A :class:`FormAccuracy` of the error norms ``error`` (N,) [m]."""
    return FormAccuracy(form, file, on, data, int(error.size), float(error.mean()),
                        float(np.sqrt(np.mean(error ** 2))), float(error.max()), frame_rms)
