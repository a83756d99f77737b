"""The result ``export`` writes (``DIR/accuracy.json``): every delivered form and what it reaches.

A result of its own kind (``"kind": "export"``, :data:`tcr_accuracy.results.kinds.KINDS`), read
back through the one reader (:func:`tcr_accuracy.read_result`) by ``report``, which
judges each form the customer receives against the campaign's limits:

* ``accuracy``: per form (full model, URDF alone, UR calibration file, DH tables, nominal) its
  TCP position error's mean, RMS and max on the measured poses, on held-out poses (a check set) and,
  for the full model, the diagnosis' k-fold held-out figure (:class:`~tcr_accuracy.asbuilt.accuracy.FormAccuracy`);
* ``point_sets``: the measured and held-out points' moments and box in the tracker frame
  (:class:`~tcr_accuracy.frames.uncertainty_budget.PointSet`), what the uncertainty budget needs
  (the instrument's distance to them, each form's frame registration);
* ``reach_mm``: the farthest measured point from the robot's base (the temperature contribution).

Lengths in mm in the file, m in the object.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..frames.uncertainty_budget import PointSet
from ..io.json_values import JsonForm
from .accuracy import FormAccuracy

#: The value of the file's ``kind`` key.
KIND = "export"


@dataclass(frozen=True)
class ExportResult(JsonForm):
    """What an export reaches, as its result file holds it.

    Attributes
    ----------
    diagnosis : str
        The diagnosis' file name (no folder: the file may leave the machine).
    robot, robot_source, tool_frame, measured_frame : str
    accuracy : tuple of FormAccuracy
    point_sets : dict of str to PointSet
        ``"measured"`` and, with a check set, ``"held-out"``; tracker frame [m].
    reach : float or None
        The farthest measured point from the robot's base [m].
    summary : dict
        The rest of the file as written (measured point on the tool frame, refit, tables, ...).
    document : dict or None
        The JSON form it was read from (None when built by an export); :meth:`to_dict` gives it
        back as it was.

    Examples
    --------
    >>> import pathlib
    >>> import tempfile
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> fitted = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    >>> export = tcr.build_export(tcr.AsBuiltModel.from_diagnosis(robot, fitted), measured)
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "accuracy.json"
    >>> _ = path.write_text(export.result("diagnosis.json", measured).to_json())
    >>> result = tcr.read_result(path)
    >>> type(result).__name__, result.forms()[-1]
    ('ExportResult', 'nominal')
    """

    diagnosis: str
    robot: str
    robot_source: str
    tool_frame: str
    measured_frame: str
    accuracy: tuple = ()
    point_sets: dict = field(default_factory=dict)
    reach: float | None = None
    summary: dict = field(default_factory=dict)
    document: dict | None = field(default=None, repr=False, compare=False)

    def forms(self) -> list[str]:
        """The forms, in their order, the nominal last."""
        return list(dict.fromkeys(a.form for a in self.accuracy))

    def figures(self, form: str) -> list[FormAccuracy]:
        """A form's figures (k-fold held-out, held-out, measured: each there is)."""
        return [a for a in self.accuracy if a.form == form]

    def to_dict(self) -> dict:
        """JSON-ready (mm); a result read from a file gives back that file's document."""
        if self.document is not None:
            return dict(self.document)
        return {"kind": KIND, "diagnosis": self.diagnosis, "robot": self.robot, "robot_source": self.robot_source,
                "tool_frame": self.tool_frame, "measured_frame": self.measured_frame, **self.summary,
                "accuracy": [a.to_dict() for a in self.accuracy],
                "point_sets": {k: p.to_dict() for k, p in self.point_sets.items()},
                "reach_mm": None if self.reach is None else self.reach * 1e3}

    @classmethod
    def from_dict(cls, doc: dict, source: str = "") -> "ExportResult":
        """Of its JSON form, a document the one reader checked (a file: :func:`tcr_accuracy.read_result`).

        Parameters
        ----------
        doc : dict
        source : str
            The file it came from, for messages.

        Returns
        -------
        ExportResult
        """
        own = {"kind", "diagnosis", "robot", "robot_source", "tool_frame", "measured_frame", "accuracy", "point_sets",
               "reach_mm"}
        reach = doc.get("reach_mm")
        return cls(diagnosis=doc["diagnosis"], robot=doc["robot"], robot_source=doc.get("robot_source", ""),
                   tool_frame=doc.get("tool_frame", ""), measured_frame=doc.get("measured_frame", ""),
                   accuracy=tuple(FormAccuracy.from_dict(a) for a in doc["accuracy"]),
                   point_sets={k: PointSet.from_dict(p) for k, p in (doc.get("point_sets") or {}).items()},
                   reach=None if reach is None else reach * 1e-3,
                   summary={k: v for k, v in doc.items() if k not in own}, document=doc)


__all__ = ["ExportResult", "KIND"]
