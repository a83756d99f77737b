"""The calibration in every form a controller or a tool takes, each with its own accuracy.

:func:`build_export` turns a full :class:`~tcr_accuracy.asbuilt.model.AsBuiltModel` and the
measurements it was fitted to into:

* the **calibration geometry** (:mod:`tcr_accuracy.asbuilt.refit`): the URDF-expressible robot
  nearest the full model over the calibrated workspace; the robot's TCP frame (``tool0``) as the
  maker built it, the measured point a frame of its own on it;
* the forms that carry that geometry: the **URDF**, the **DH** and **MDH** tables (Hayati's beta
  for parallel axes), the **maker's published convention** (UR, Franka) and, for a UR arm, the
  **UR ROS 2 driver's calibration file**; each checked against the geometry's forward
  kinematics (1e-9 m) when built;
* the **full model** itself (the one model file, :mod:`tcr_accuracy.asbuilt.model_file`);
* what each form reaches (:mod:`tcr_accuracy.asbuilt.accuracy`), next to the nominal robot with
  the fitted measured point.

``tcr-accuracy export`` and ``diagnose --as-built-urdf`` write these; nothing here writes files.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from ..io.measurement_set import MeasurementSet
from ..frames.uncertainty_budget import PointSet
from ..model.errors import ErrorModel
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel
from ..prediction.nominal import nominal_errors
from .accuracy import FormAccuracy, MeasuredPoses, error_statistics, form_accuracy
from .export_result import ExportResult
from .dh import DhTable, NoDhForm, dh_table, mdh_table
from .maker_dh import maker_table, published_table
from .model import AsBuiltModel
from .model_file import model_document, model_yaml
from .refit import CalibrationGeometry, refit_geometry
from .ur_calibration import is_ur, tool0_poses, ur_kinematics
from .urdf import as_built_urdf

#: File names in an export folder.
URDF_FILE, MODEL_FILE, UR_FILE = "as_built.urdf", "as_built.yaml", "ur_calibration.yaml"
#: The export's result file (kind "export", :mod:`tcr_accuracy.asbuilt.export_result`).
RESULT_FILE = "accuracy.json"


@dataclass(frozen=True)
class TableForm:
    """A DH-type table of the calibration: the nominal robot's and the calibrated one's.

    name : "DH", "MDH" or the maker's ("UR DH", "Franka MDH"); file : its CSV's name
    nominal, as_built : DhTable (the same frame choices; as built - nominal is the correction)
    maker : who publishes the convention ("" for the generic tables)
    """

    name: str
    file: str
    nominal: DhTable
    as_built: DhTable
    maker: str = ""


@dataclass(frozen=True)
class AsBuiltExport:
    """A calibration in every form, with what each reaches.

    model : the full model; geometry : the refitted calibration geometry
    calibrated : RobotModel whose TCP is the measured point (the URDF's chain)
    flange : RobotModel whose TCP is the robot's own TCP frame as built (what the tables end at)
    measured_offset : (4, 4) the robot's TCP frame -> the measured point
    tables : the DH-type forms; not_tabled : form -> why it has no table
    ur : the UR calibration document, or None
    accuracy : every form's FormAccuracy (measured, held-out, k-fold)
    urdf_file, model_file : the names the URDF and the model file are written under
    """

    model: AsBuiltModel
    geometry: CalibrationGeometry
    calibrated: RobotModel
    flange: RobotModel
    measured_offset: np.ndarray
    tables: tuple
    not_tabled: dict
    ur: dict | None
    accuracy: tuple = field(default=())
    urdf_file: str = URDF_FILE
    model_file: str = MODEL_FILE

    @property
    def measured_frame(self) -> str:
        return f"{self.model.robot.tool_frame}_measured"

    def urdf_text(self, comment: str | None = None) -> str:
        """The calibration URDF (robot name ``<robot>_as_built``)."""
        text, _ = as_built_urdf(self.model.robot, self.geometry.x, name=f"{self.model.robot.name}_as_built",
                                comment=comment)
        return text

    def model_text(self, **informational) -> str:
        """The one model file's text (:mod:`tcr_accuracy.asbuilt.model_file`), with the URDF it goes with."""
        extra = {"urdf": self.urdf_file, "urdf_measured_frame": self.measured_frame}
        extra["accuracy"] = [a.to_dict() for a in self.accuracy]
        return model_yaml(model_document(self.model, **extra, **informational))

    def result(self, diagnosis: str, measured: MeasurementSet, held_out: MeasurementSet | None = None) -> ExportResult:
        """The export's result file (:class:`~tcr_accuracy.asbuilt.export_result.ExportResult`):
        ``diagnosis`` the diagnosis' file name; ``measured`` and ``held_out`` the poses its figures are on."""
        sets = {"measured": PointSet.of(measured.position)}
        if held_out is not None:
            sets["held-out"] = PointSet.of(held_out.position)
        reach = float(np.max(np.linalg.norm(self.model.tcp_poses(measured.q, measured.context).position, axis=1)))
        summary = {k: v for k, v in self.to_dict().items() if k not in ("robot", "robot_source", "tool_frame",
                                                                        "measured_frame", "accuracy")}
        return ExportResult(diagnosis, self.model.robot.name, self.model.robot_source, self.model.robot.tool_frame,
                            self.measured_frame, tuple(self.accuracy), sets, reach, summary)

    def to_dict(self) -> dict:
        """JSON-ready summary, lengths in mm and angles in deg."""
        offset = self.measured_offset
        return {
            "robot": self.model.robot.name, "robot_source": self.model.robot_source,
            "tool_frame": self.model.robot.tool_frame, "measured_frame": self.measured_frame,
            "measured_point_on_tool_frame_mm": (offset[:3, 3] * 1e3).tolist(),
            "measured_point_rotation_vector_deg": np.degrees(pin.log3(offset[:3, :3])).tolist(),
            "refit": {"rms_to_full_model_mm": self.geometry.rms * 1e3, "max_to_full_model_mm": self.geometry.max * 1e3,
                      "measured_poses": self.geometry.n_measured, "poses_between": self.geometry.n_sampled,
                      "parameters_fitted": len(self.geometry.fitted)},
            "accuracy": [a.to_dict() for a in self.accuracy],
            "tables": [t.name for t in self.tables], "not_tabled": dict(self.not_tabled),
            "ur_calibration": self.ur is not None,
        }


def build_export(model: AsBuiltModel, measured: MeasurementSet, held_out: MeasurementSet | None = None, *,
                 payload_kg: float | None = None, kfold: dict | None = None, urdf_file: str = URDF_FILE,
                 model_file: str = MODEL_FILE) -> AsBuiltExport:
    """Every form of the calibration and what each reaches.

    Parameters
    ----------
    model : AsBuiltModel
        The full model (a diagnosis').
    measured : MeasurementSet
        The measurements it was fitted to (the calibrated workspace; each session gets each form's
        own tracker frame). Its ``source`` labels the figures.
    held_out : MeasurementSet, optional
        Measurements it was not fitted to, in the first session's tracker frame.
    payload_kg : float, optional
        The load the static forms hold [kg] (default: each measured row's).
    kfold : dict, optional
        The diagnosis' own k-fold held-out figures of the full model: ``mean``, ``rms``, ``max`` [m],
        ``folds``, ``n``.
    urdf_file, model_file : str
        The names the URDF and the model file will be written under (named in the figures).

    Returns
    -------
    AsBuiltExport

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    >>> export = tcr.build_export(tcr.AsBuiltModel.from_diagnosis(robot, d), measured)
    >>> [a.form for a in export.accuracy][:2]
    ['full model', 'URDF alone']
    """
    measured, held_out = (_poses(m) for m in (measured, held_out))
    robot = model.robot
    geometry = refit_geometry(model, measured.q, measured.context, payload_kg=payload_kg)
    em = ErrorModel(robot)
    calibrated = em.perturbed_robot(geometry.x)
    x_flange = geometry.x.copy()
    x_flange[em.tool_slice] = 0.0
    flange = em.perturbed_robot(x_flange)
    offset = pin.exp6(geometry.x[em.tool_slice]).homogeneous
    tables, not_tabled = _tables(model, flange)
    ur = ur_kinematics(flange, robot, model.robot_source) if is_ur(model.robot_source, robot) else None
    export = AsBuiltExport(model, geometry, calibrated, flange, offset, tuple(tables), not_tabled, ur, (),
                           urdf_file, model_file)
    return replace(export, accuracy=tuple(_accuracies(export, measured, held_out, kfold)))


def _poses(measurements) -> MeasuredPoses | None:
    """The rows the figures are computed on, labelled by their source (file names)."""
    if measurements is None or isinstance(measurements, MeasuredPoses):
        return measurements
    return MeasuredPoses.of(measurements, str(measurements.source))


def _tables(model: AsBuiltModel, flange: RobotModel) -> tuple[list[TableForm], dict]:
    robot = model.robot
    tables, missing = [], {}
    for name, build in (("DH", dh_table), ("MDH", mdh_table)):
        try:
            nominal = build(robot)
            tables.append(TableForm(name, f"{name.lower()}.csv", nominal, build(flange, robot, reference=nominal)))
        except NoDhForm as exc:
            missing[name] = str(exc)
    maker = published_table(model.robot_source, robot)
    if maker is not None:
        published, nominal = maker
        name = f"{'UR' if published.maker.startswith('Universal') else 'Franka'} {published.convention}"
        try:
            tables.append(TableForm(name, f"{model.robot_source.lower()}_{published.convention.lower()}.csv", nominal,
                                    maker_table(flange, robot, published), published.maker))
        except NoDhForm as exc:
            missing[name] = str(exc)
    return tables, missing


def _accuracies(export: AsBuiltExport, measured: MeasuredPoses, held_out, kfold) -> list[FormAccuracy]:
    model, offset = export.model, export.measured_offset

    def full(q, context, later):
        return model.tcp_poses(q, model.state_context(context, len(q)) if later else context).position

    def urdf(q, context, later):
        return tcp_poses(export.calibrated, q).position

    def table(t: DhTable):
        return lambda q, context, later: np.array([(t.tcp(v) @ offset)[:3, 3] for v in q])

    def ur(q, context, later):
        return (tool0_poses(export.ur, q) @ offset)[:, :3, 3]

    forms = [("full model", export.model_file, full), ("URDF alone", export.urdf_file, urdf)]
    if export.ur is not None:
        forms.append(("UR calibration file", UR_FILE, ur))
    forms += [(f"{t.name} table", t.file, table(t.as_built)) for t in export.tables]
    out = []
    if kfold:
        out.append(FormAccuracy("full model", export.model_file, "k-fold held-out",
                                f"{kfold.get('folds', '')}-fold cross-validation of the diagnosis", int(kfold.get("n", 0)),
                                float(kfold["mean"]), float(kfold["rms"]), float(kfold["max"])))
    for form, file, kinematics in forms:
        out += form_accuracy(form, file, kinematics, measured, held_out)
    # the nominal robot: its own tracker frame and TCP offset fitted (prediction.nominal, the one definition)
    nominal = nominal_errors(model.robot, measured.q, measured.position, session=measured.session,
                             held_out=None if held_out is None else (held_out.q, held_out.position))
    for figure, data in zip(nominal, (measured, held_out)):
        out.append(error_statistics("nominal", "", figure.on, data.label, figure.error,
                                    figure.registration.residual_rms))
    return out
