"""The calibrated robot a diagnosis found, written for other tools and read back.

:class:`AsBuiltModel` is the fitted model in the robot's base frame: the nominal robot and
every chosen effect with its full parameter vector (the ``frames`` base twist is the tracker's,
so it is left out). Its :meth:`~AsBuiltModel.tcp_poses` are the diagnosis' prediction,
non-geometric effects (compliance under the payload, backlash, thermal expansion, gear
errors, ...) included, at each row's context.

:func:`write_as_built_model` writes it as

* ``<name>.urdf``: the geometry (frames' TCP offset, joint offsets, geometry) built into a URDF
  (:func:`tcr_accuracy.model.asbuilt.as_built_urdf`), for tools that take a URDF;
* ``<name>.yaml``: everything :func:`load_as_built` needs to rebuild the whole model: how to
  load the nominal robot (a name or the URDF's path), the TCP frame, each effect's parameters
  by name [SI] and the tracker frame.

Geometry in a URDF is exact to the printed digits; the non-geometric effects are evaluated on
the nominal robot's masses and geometry, as the fit did, so a loaded model gives the fitted
model's TCP to rounding (1e-12 m), not to the first order of the geometric errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..effects import effect_class, make_effect, predict_poses, total_perturbation
from ..exceptions import InputError
from ..model.errors import ErrorModel
from ..model.kinematics import TcpPoses
from ..model.robot import RobotModel, load_robot

#: Format tag of the YAML file (checked on load).
FORMAT = "tcr-accuracy as-built model 1"


@dataclass
class AsBuiltModel:
    """A fitted robot: nominal robot + effects with their parameters, in the robot's base frame.

    Attributes
    ----------
    robot : RobotModel, the nominal robot
    parameters : dict, effect name -> {parameter name: value [SI]}, in vocabulary order
    robot_source : str, how to load the nominal robot (example-robot-data name, ``tool_changer``
        or a URDF path)
    tracker_from_base : (4, 4) ndarray or None, the fitted tracker frame (``p_tracker = M p_base``)
    options : dict, effect name -> the options it was fitted with (a cyclic error's highest order,
        thermal's reference temperature); the sessions' tracker frames are not the robot's and are left out
    """

    robot: RobotModel
    parameters: dict
    robot_source: str = "tool_changer"
    tracker_from_base: np.ndarray | None = None
    options: dict = field(default_factory=dict)
    effects: list = field(init=False)

    def __repr__(self) -> str:
        n = sum(len(v) for v in self.parameters.values())
        tracker = ", with tracker frame" if self.tracker_from_base is not None else ""
        return (f"AsBuiltModel({self.robot.name!r}, effects [{', '.join(self.parameters)}], {n} parameters"
                f"{tracker})")

    def __post_init__(self) -> None:
        self.options = {e: {k: v for k, v in (o or {}).items() if not (e == "frames" and k == "sessions")}
                        for e, o in self.options.items()}
        self.effects = [make_effect(e, self.robot, **self.options.get(e, {})) for e in self.parameters]
        vectors = []
        for effect in self.effects:
            values = self.parameters[effect.name]
            if effect.name == "frames":  # the tracker frames (one per session) are the setup's, not the robot's
                values = {n: v for n, v in values.items() if not n.startswith("frames.base.")}
            names = effect.parameter_names()
            unknown = set(values) - set(names)
            if unknown:
                raise InputError(f"as-built model: {effect.name} has no parameter {sorted(unknown)[0]} on "
                                 f"{self.robot.name}")
            vector = np.array([float(values.get(n, 0.0)) for n in names])
            if effect.name == "frames":  # the base twist places the tracker, not the robot
                vector[[i for i, n in enumerate(names) if n.startswith("frames.base.")]] = 0.0
            vectors.append(vector)
        self._vectors = vectors

    @classmethod
    def from_diagnosis(cls, robot: RobotModel, diagnosis, robot_source: str = "tool_changer") -> "AsBuiltModel":
        """The model a :class:`~tcr_accuracy.diagnosis.result.Diagnosis` fitted (first measured frame)."""
        options = {e: dict(o) for e, o in diagnosis.effect_options.items()}
        parameters = {e: dict(zip(make_effect(e, robot, **options.get(e, {})).parameter_names(), map(float, vector)))
                      for e, vector in diagnosis.effect_parameters.items()}
        return cls(robot, parameters, robot_source, np.asarray(diagnosis.tracker_transform, dtype=float), options)

    # -- the model ---------------------------------------------------------------------
    def tcp_poses(self, q, context=None) -> TcpPoses:
        """TCP poses (base frame) of the calibrated robot at commanded joints q (N, n_joints) [SI],
        every effect included, at the rows' MeasurementContext (payload, temperature, ...)."""
        return predict_poses(self.robot, self.effects, self._vectors, q, context)

    def geometric_errors(self) -> np.ndarray:
        """(n_params,) the geometric effects as one error vector of
        :class:`~tcr_accuracy.model.errors.ErrorModel` (joint offsets in its drive part), what
        the as-built URDF carries."""
        em = ErrorModel(self.robot)
        pairs = [(e, v) for e, v in zip(self.effects, self._vectors) if effect_class(e.name).geometric]
        q0 = self.robot.working_pose[None]
        dq, x = total_perturbation(self.robot, [e for e, _ in pairs], [v for _, v in pairs], q0)
        out = x[0].copy()
        out[em.drive_slice] += dq[0]
        return out

    def geometric_robot(self) -> RobotModel:
        """The robot with the geometric effects built in (what the as-built URDF loads as)."""
        return ErrorModel(self.robot).perturbed_robot(self.geometric_errors())

    def tcp_offset(self) -> np.ndarray:
        """(3,) the fitted TCP offset in the TCP frame [m] (``frames.tool.*``; zeros without frames)."""
        frames = self.parameters.get("frames", {})
        return np.array([frames.get(f"frames.tool.{c}", 0.0) for c in ("dx", "dy", "dz")])

    def joint_offsets(self) -> np.ndarray:
        """(n_joints,) fitted joint zero offsets [rad, m] (zeros without the joint_offsets effect)."""
        offsets = self.parameters.get("joint_offsets", {})
        return np.array([offsets.get(f"joint_offsets.{j}", 0.0) for j in self.robot.joint_names])

    def to_dict(self) -> dict:
        """The YAML document (SI)."""
        return {
            "format": FORMAT,
            "robot": self.robot.name,
            "robot_source": self.robot_source,
            "tool_frame": self.robot.tool_frame,
            "units": "SI (m, rad, rad/Nm, m/N, 1/K)",
            "note": "tcp_poses = the nominal robot with these effects, frames' base twist left out (it is the "
                    "tracker's); tracker_from_base: p_tracker = M p_base",
            "effects": {e: {k: float(v) for k, v in p.items()} for e, p in self.parameters.items()},
            "options": {e: dict(o) for e, o in self.options.items() if o},
            "tracker_from_base": None if self.tracker_from_base is None else
            [[float(v) for v in row] for row in self.tracker_from_base],
        }


def write_as_built_model(model: AsBuiltModel, folder: Path, name: str) -> dict[str, str]:
    """The texts of ``<name>.urdf`` and ``<name>.yaml`` (file name -> text); the caller writes them."""
    import yaml

    from ..model.asbuilt import as_built_urdf

    urdf, tool_frame = as_built_urdf(model.robot, model.geometric_errors(), name=f"{model.robot.name}_as_built")
    doc = model.to_dict()
    doc["urdf"] = f"{name}.urdf"
    doc["urdf_tool_frame"] = tool_frame
    return {f"{name}.urdf": urdf, f"{name}.yaml": yaml.safe_dump(doc, sort_keys=False)}


def load_as_built(path) -> AsBuiltModel:
    """The calibrated robot written by ``tcr-accuracy export`` (its ``.yaml``, or the ``.urdf``
    next to it), whose :meth:`AsBuiltModel.tcp_poses` include the non-geometric effects.

    Parameters
    ----------
    path : str or Path
        The ``.yaml`` file, or the ``.urdf`` written next to it.

    Returns
    -------
    AsBuiltModel
        The nominal robot and every effect with its fitted parameters [SI].
    """
    from ..input_files import read_settings_file

    path = Path(path)
    if path.suffix.lower() == ".urdf":
        path = path.with_suffix(".yaml")
    doc = read_settings_file(path, "as-built model", "yaml")  # the one opener: regular file, size, depth
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InputError(f"{path}: not an as-built model written by tcr-accuracy export (no 'format: {FORMAT}')")
    for key in ("robot_source", "tool_frame", "effects"):
        if key not in doc:
            raise InputError(f"{path}: key {key!r} is missing")
    source = doc["robot_source"]
    robot = load_robot(None if source == "tool_changer" else source, doc["tool_frame"])
    effects = doc["effects"] or {}
    if not isinstance(effects, dict) or not all(isinstance(v, dict) for v in effects.values()):
        raise InputError(f"{path}: 'effects' must map effect names to {{parameter: value}}")
    tracker = doc.get("tracker_from_base")
    options = doc.get("options") or {}
    if not isinstance(options, dict) or not all(isinstance(v, dict) for v in options.values()):
        raise InputError(f"{path}: 'options' must map effect names to {{option: value}}")
    return AsBuiltModel(robot, {str(e): dict(p) for e, p in effects.items()}, source,
                        None if tracker is None else np.asarray(tracker, dtype=float), options)
