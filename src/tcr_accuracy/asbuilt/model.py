"""The calibrated robot a diagnosis found: the nominal robot and every fitted effect.

:class:`AsBuiltModel` is the fitted model in the robot's base frame: the nominal robot and
every chosen effect with its full parameter vector (the ``frames`` base twist is the tracker's,
so it is left out). Its :meth:`~AsBuiltModel.tcp_poses` are the diagnosis' prediction,
non-geometric effects (compliance under the payload, backlash, thermal expansion, gear
errors, drift, ...) included, at each row's context.

The static forms a controller takes (a URDF, DH tables, a UR calibration file) hold the robot
in one state: **the end of the measurement campaign** (:meth:`AsBuiltModel.state_context`), the
latest one measured, with whatever drifted during the campaign drifted.

Where it is written and read: :mod:`tcr_accuracy.asbuilt.model_file`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..effects import effect_class, predict_poses, total_perturbation
from ..effects.file_values import checked_effect, parameter_vector

#: The frames effect's options about the measurement sessions (each session's tracker frame and TCP
#: offset belong to that session's setup): the as-built robot carries the first session's
SESSION_OPTIONS = ("sessions", "session_frames", "session_tools")
from ..exceptions import InputError
from ..model.context import MeasurementContext
from ..model.errors import ErrorModel
from ..model.kinematics import TcpPoses
from ..model.robot import RobotModel


@dataclass
class AsBuiltModel:
    """A fitted robot: nominal robot + effects with their parameters, in the robot's base frame.

    Attributes
    ----------
    robot : RobotModel, the nominal robot
    parameters : dict, effect name -> {parameter name: value [SI]}, in vocabulary order
    robot_source : str, how to load the nominal robot (example-robot-data name, ``tool_changer``
        or a URDF path); default: the robot's own (:attr:`RobotModel.robot_source`)
    trackerMbase : (4, 4) ndarray or None, the fitted tracker frame (``p_tracker = trackerMbase @ p_base``)
    options : dict, effect name -> the options it was fitted with (a cyclic error's highest order,
        thermal's reference temperature); the sessions' tracker frames are not the robot's and are left out
    source : str, where the values came from (a file name), named in error messages
    source_keys : (str, str), the keys of the parameters and the options in that file

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    >>> model = tcr.AsBuiltModel.from_diagnosis(robot, d)
    >>> model.robot_source, model.tcp_poses(measured.q[:2]).position.shape
    ('tool_changer', (2, 3))
    """

    robot: RobotModel
    parameters: dict
    robot_source: str | None = None
    trackerMbase: np.ndarray | None = None
    options: dict = field(default_factory=dict)
    source: str = "as-built model"
    source_keys: tuple = ("effects", "options")
    effects: list = field(init=False)

    def __repr__(self) -> str:
        n = sum(len(v) for v in self.parameters.values())
        tracker = ", with tracker frame" if self.trackerMbase is not None else ""
        return (f"AsBuiltModel({self.robot.name!r}, effects [{', '.join(self.parameters)}], {n} parameters"
                f"{tracker})")

    def __post_init__(self) -> None:
        if self.robot_source is None:
            self.robot_source = self.robot.robot_source
        if self.robot_source is None:
            raise InputError(f"{self.source}: robot_source: {self.robot.name} was not loaded by load_robot (built from "
                             "URDF text, or a perturbed copy): give robot_source, how load_robot loads it again "
                             "(an example-robot-data name, tool_changer or a URDF path)", parameter="robot_source")
        if not isinstance(self.parameters, dict) or not isinstance(self.options or {}, dict):
            raise InputError(f"{self.source}: parameters and options must map effect names to mappings")
        self.options = {e: {k: v for k, v in (o or {}).items() if not (e == "frames" and k in SESSION_OPTIONS)}
                        for e, o in (self.options or {}).items()}
        self.effects, vectors = [], []
        for name, values in self.parameters.items():
            parameters_key, options_key = self.source_keys
            effect = checked_effect(name, self.robot, self.options.get(name), f"{self.source}: {options_key}")
            if name == "frames" and isinstance(values, dict):  # the tracker frames are the setup's, not the robot's,
                # and so are the later sessions' TCP offsets (frames.tool.<session>.dx): the first session's is kept
                values = {n: v for n, v in values.items() if not str(n).startswith("frames.base.") and
                          not (str(n).startswith("frames.tool.") and str(n).count(".") > 2)}
            vectors.append(parameter_vector(effect, values, f"{self.source}: {parameters_key}.{name}"))
            self.effects.append(effect)
        self._vectors = vectors

    @property
    def tracker_from_base(self) -> np.ndarray | None:
        """Deprecated alias of :attr:`trackerMbase` (until 0.2): one name for the base-to-tracker transform."""
        import warnings

        warnings.warn("AsBuiltModel.tracker_from_base is deprecated and will be removed in 0.2; use "
                      "AsBuiltModel.trackerMbase", DeprecationWarning, stacklevel=2)
        return self.trackerMbase

    @classmethod
    def from_diagnosis(cls, robot: RobotModel, diagnosis, robot_source: str | None = None) -> "AsBuiltModel":
        """The model a :class:`~tcr_accuracy.diagnosis.result.Diagnosis` fitted (first measured
        frame), fitted here or read from its JSON form.

        Parameters
        ----------
        robot : RobotModel
            The robot it was fitted to (the first measured frame's).
        diagnosis : Diagnosis
        robot_source : str, optional
            How to load the robot again; default the robot's own (:attr:`RobotModel.robot_source`,
            set by :func:`~tcr_accuracy.model.robot.load_robot`), so the model file loads back.

        Returns
        -------
        AsBuiltModel
        """
        from ..effects import make_effect

        if diagnosis.robot_name != robot.name:
            raise InputError(f"{diagnosis.file or 'diagnosis'}: a diagnosis of {diagnosis.robot_name}, not of "
                             f"{robot.name}", parameter="robot")
        options = {e: dict(o) for e, o in diagnosis.effect_options.items()}
        parameters = {}
        for e, vector in diagnosis.effect_parameters.items():
            effect = make_effect(e, robot, **{k: v for k, v in options.get(e, {}).items()
                                              if not (e == "frames" and k in SESSION_OPTIONS)})
            names = effect.parameter_names()
            if e == "frames" and "sessions" in options.get(e, {}):  # the first session's frame and TCP offset
                fitted = make_effect(e, robot, **options[e]).parameter_names()
                if len(fitted) == len(vector):
                    by_name = dict(zip(fitted, vector))
                    vector = [by_name.get(n, 0.0) for n in names]
            if len(names) != len(vector):
                raise InputError(f"{diagnosis.file or 'diagnosis'}: {e} has {len(vector)} parameters, {e} of "
                                 f"{robot.name} has {len(names)}: a diagnosis of another robot", parameter="robot")
            parameters[e] = dict(zip(names, map(float, vector)))
        return cls(robot, parameters, robot_source, np.asarray(diagnosis.trackerMbase, dtype=float), options,
                   source=diagnosis.file or "diagnosis")

    # -- the model ---------------------------------------------------------------------
    def tcp_poses(self, q, context=None) -> TcpPoses:
        """TCP poses (base frame) of the calibrated robot at commanded joints q (N, n_joints) [SI],
        every effect included, at the rows' MeasurementContext (payload, temperature, ...)."""
        return predict_poses(self.robot, self.effects, self._vectors, q, context)

    def state_context(self, context: MeasurementContext | None, n: int) -> MeasurementContext:
        """The rows' context (or the defaults for ``n`` rows) at the end of the measurement
        campaign: the state the static forms (URDF, tables) hold, drift included in full."""
        context = MeasurementContext.defaults(n, self.robot.n_joints) if context is None else context
        end_time, end_order = None, None
        for effect in self.effects:  # effects of the campaign's time (drift) know its start and span
            if "time_s" in effect.context_columns and {"start", "span"} <= set(vars(effect)):
                end = float(effect.start) + float(effect.span)
                if getattr(effect, "time_axis", "order") == "time_s":
                    end_time = end
                else:
                    end_order = end
        return replace(context, time_s=None if end_time is None else np.full(n, end_time),
                       order=None if end_order is None else np.full(n, end_order))

    def geometric_errors(self) -> np.ndarray:
        """(n_params,) the geometric effects as one error vector of
        :class:`~tcr_accuracy.model.errors.ErrorModel` (joint offsets in its drive part): the
        diagnosis' own geometric part, before any refit."""
        em = ErrorModel(self.robot)
        pairs = [(e, v) for e, v in zip(self.effects, self._vectors) if effect_class(e.name).geometric]
        q0 = self.robot.working_pose[None]
        dq, x = total_perturbation(self.robot, [e for e, _ in pairs], [v for _, v in pairs], q0)
        out = x[0].copy()
        out[em.drive_slice] += dq[0]
        return out

    def tcp_offset(self) -> np.ndarray:
        """(3,) the fitted TCP offset in the TCP frame [m] (``frames.tool.*``; zeros without frames)."""
        frames = self.parameters.get("frames", {})
        return np.array([float(frames.get(f"frames.tool.{c}", 0.0)) for c in ("dx", "dy", "dz")])

    def joint_offsets(self) -> np.ndarray:
        """(n_joints,) fitted joint zero offsets [rad, m] (zeros without the joint_offsets effect)."""
        offsets = self.parameters.get("joint_offsets", {})
        return np.array([float(offsets.get(f"joint_offsets.{j}", 0.0)) for j in self.robot.joint_names])

    def measured_point_robot(self) -> RobotModel:
        """The nominal robot whose TCP is the measured point (the fitted TCP offset on the TCP
        frame): what a controller given only that offset computes."""
        em = ErrorModel(self.robot)
        x = em.zeros()
        x[em.tool_slice.start:em.tool_slice.start + 3] = self.tcp_offset()
        return em.perturbed_robot(x, name=self.robot.name)
