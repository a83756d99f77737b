"""Stage 1: register the measurements -- each session's tracker frame, the tracker's drift seen
by base references, and the measured targets in the robot's base frame.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ...frames.drift import tracker_drift
from ...frames.noise import NoiseEstimate
from ...frames.sessions import register_sessions, to_base_frame
from ...io.measurements import MeasurementSet
from ...model.gravity import gravity_torque
from ...model.kinematics import tcp_poses
from ...model.robot import RobotModel
from ..bases import Part

#: [rad] how far a session's own closed-form tracker frame may turn against one frame registered on
#: every session's rows for that one frame to map them all: within it the sessions' frames are a
#: question for the fit (:mod:`.setup` chooses whether each session has its own), beyond it the
#: tracker moved and each session is registered on its own. 3 deg: the base twist's columns, taken at
#: the shared frame, are then within 5 % of a session's own, which Gauss-Newton's steps absorb.
SHARED_FRAME_REACH = 0.05

#: the context fields a MeasurementSet may have measured (the others take defaults)
MEASURED_CONTEXT = ("payload_kg", "temperature_c", "direction")


def measured_context(measurements: MeasurementSet) -> tuple[str, ...]:
    """The context fields the measurements actually carry (``payload_kg``, ``temperature_c``,
    ``direction``); the others are defaults."""
    return tuple(k for k in MEASURED_CONTEXT if getattr(measurements, k, None) is not None)


@dataclass(frozen=True)
class MeasuredFrame:
    """One measured frame of the rows: the robot whose TCP it is, its measurements (drift
    corrected) and its name."""

    robot: RobotModel
    measurements: MeasurementSet
    label: str


@dataclass(frozen=True)
class RegisteredMeasurements:
    """What stage 1 found (SI units).

    Attributes
    ----------
    frames : tuple of MeasuredFrame
        The measured frames, positions corrected for the tracker's drift (first: the main one).
    parts : tuple of Part
        The same frames with their targets in the robot's base frame, for the fit engine.
    nominal : tuple of TcpPoses
        Each frame's nominal poses at the commanded joints.
    stations : tuple of (ndarray (3, 3), ndarray (3,))
        Each session's closed-form tracker frame: ``p_tracker = R p_base + t`` [m] (the same for
        every session when one frame maps them all, see :attr:`own_frames`).
    session_labels : tuple of str
        The sessions' labels (empty for one session).
    session_of : ndarray of shape (N,)
        Each row's session.
    drift : tuple of dict
        Per session, the drift the base references show (JSON form, mm keys).
    reference_noise : NoiseEstimate or None
        The instrument's noise from the references' scatter about their drift.
    references : tuple
        The base references, drift corrected: (frame, place (3,), measured (N, 3), time_s).
    orientation_weight : float
        [m/rad] weight of measured orientation rows.
    gravity_torque : ndarray of shape (N, n_joints)
        The gravity torque on each joint of the main frame's chain [N m, N].
    measured_context : frozenset of str
        The context fields measured in any frame.
    instrument : Instrument or None
        The instrument's specification the points are weighed by.
    notes : tuple of str
    own_frames : str
        Why each session was registered on its own (the tracker moved beyond
        :data:`SHARED_FRAME_REACH`: a frame per session, not the data's choice); empty when one frame
        registered on every row maps them all (then the fit chooses what each session owns).
    """

    frames: tuple
    parts: tuple
    nominal: tuple
    stations: tuple
    session_labels: tuple
    session_of: np.ndarray
    drift: tuple
    reference_noise: NoiseEstimate | None
    references: tuple
    orientation_weight: float
    gravity_torque: np.ndarray
    measured_context: frozenset
    notes: tuple
    instrument: object = None
    own_frames: str = ""

    @property
    def robot(self) -> RobotModel:
        """The main measured frame's robot."""
        return self.frames[0].robot

    @property
    def measurements(self) -> MeasurementSet:
        """The main measured frame's measurements (drift corrected)."""
        return self.frames[0].measurements

    @property
    def n_rows(self) -> int:
        return len(self.frames[0].measurements)


def register_measurements(frames: list[MeasuredFrame], references=(), orientation_weight: float | None = None,
                          instrument=None) -> RegisteredMeasurements:
    """Stage 1 of the diagnosis.

    Parameters
    ----------
    frames : list of MeasuredFrame
        The measured frames (row-aligned).
    references : list of (frame, place (3,) [m], measured (N, 3) [m], time_s (N,) or None)
        Base references: frames fixed to the robot's base, measured on the same rows.
    orientation_weight : float or None
        [m/rad] weight of measured orientation; None: the RMS spread of the measured points
        about their centre.
    instrument : Instrument or None
        The instrument's specification (:mod:`tcr_accuracy.frames.instrument`): each point's
        position rows are weighed by its noise, from the measured positions as the instrument's
        frame holds them (the instrument at the origin).
    """
    first = frames[0].measurements
    n = len(first)
    notes: list = []
    nominal = [tcp_poses(f.robot, f.measurements.q) for f in frames]
    sessions = list(first.session_labels) if len(first.session_labels) > 1 else []
    session_of = first.context.session if sessions else np.zeros(n, dtype=int)
    # base references: the tracker's drift per session, taken out of every measured position
    drift, drift_report, reference_noise = tracker_drift(list(references), session_of, max(len(sessions), 1),
                                                         sessions)
    references = list(references)
    if references:
        frames = [dataclasses.replace(f, measurements=dataclasses.replace(
            f.measurements, position=f.measurements.position - drift)) for f in frames]
        references = [(f, place, measured - drift, t) for f, place, measured, t in references]
    stations = register_sessions([p.position for p in nominal], [f.measurements.position for f in frames],
                                 session_of, sessions, references)
    own_frames = ""
    if sessions:
        shared = register_sessions([p.position for p in nominal], [f.measurements.position for f in frames],
                                   np.zeros(n, dtype=int), [], references)[0]
        turn = max(float(np.linalg.norm(Rotation.from_matrix(shared[0].T @ r).as_rotvec())) for r, _ in stations)
        if turn <= SHARED_FRAME_REACH:
            stations = [shared] * len(sessions)
        else:
            own_frames = (f"a session's own tracker frame turns by up to {np.degrees(turn):.3g} deg against one "
                          f"frame for all (more than {np.degrees(SHARED_FRAME_REACH):.3g} deg): the tracker moved, "
                          "each session is registered on its own")
    weight = orientation_weight
    if weight is None:
        points = np.concatenate([f.measurements.position for f in frames])
        weight = float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))
    parts = []
    for f in frames:
        m = f.measurements
        target_rotation = None
        if m.quaternion is not None:
            w, x, y, z = m.quaternion.T
            tracker_rotation = Rotation.from_quat(np.stack([x, y, z, w], axis=1)).as_matrix()
            station_rotation = np.stack([stations[s][0] for s in session_of])
            target_rotation = np.einsum("nji,njk->nik", station_rotation, tracker_rotation)  # R^T R_tracker
        context = dataclasses.replace(m.context, order=np.arange(n))  # these rows are the campaign: their order is
        whitening = None
        if instrument is not None:
            whitening = instrument.whitening(m.position, np.stack([stations[s][0] for s in session_of]))
        parts.append(Part(f.robot, m.q, to_base_frame(m.position, session_of, stations), context, f.label,
                          target_rotation, weight, whitening))
    if any(p.target_rotation is not None for p in parts):
        notes.append(f"measured orientation enters the fit: rotation errors [rad] weighted by {weight:.4g} m/rad "
                     "(an angle counts as the position error it makes at the measured points' RMS spread "
                     "about their centre)")
    main = frames[0].measurements
    context = parts[0].context
    tau = gravity_torque(frames[0].robot, main.q, context.payload_kg, outside_q=context.outside_q)
    measured = frozenset().union(*(set(measured_context(f.measurements)) for f in frames))
    return RegisteredMeasurements(
        frames=tuple(frames), parts=tuple(parts), nominal=tuple(nominal), stations=tuple(stations),
        session_labels=tuple(sessions), session_of=session_of, drift=tuple(drift_report),
        reference_noise=reference_noise, references=tuple(references), orientation_weight=weight,
        gravity_torque=tau, measured_context=measured, notes=tuple(notes), instrument=instrument,
        own_frames=own_frames)
