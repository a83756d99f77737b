"""An ISO 9283 pose test's result as JSON: what ``iso9283 evaluate --json`` writes, read back.

:class:`IsoTestResult` is one file: the robot, the measurements, and per test condition (load,
speed) the evaluation as measured and, where a diagnosis was given, as predicted after
compensating with it. :func:`evaluation_dict` writes one
:class:`~tcr_accuracy.iso9283.evaluate.IsoEvaluation` in the JSON form (mm, deg, s) and
:func:`evaluation_from_dict` reads it back: the figures (:class:`~tcr_accuracy.iso9283.formulas.IsoFigures`,
SI) equal to the rounding of their mm values; the measurement frame's fit is kept as the file
words it (``registration``: its summary, mm and deg), and what the file does not hold (each
pose's commanded joints, the orientation offset's matrix) is None.

A file is read with :func:`tcr_accuracy.read_result`, which checks it whole (its schema, AP_P
against its components, the summary against the poses) before building it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from ..io.json_values import JsonForm, plain
from .evaluate import IsoEvaluation
from .formulas import STANDARD_CYCLES, DirectionalVariation, DistanceFigures, IsoFigures, PoseFigures, Stabilisation, pose_name


def json_label(label):
    """A label as JSON: a whole number as an int (as the pose ids ``iso9283 plan`` writes), else text."""
    return None if label is None else int(label) if re.fullmatch(r"[+-]?\d+", str(label)) else str(label)


def _label(value):
    """A label of the JSON form back as the evaluation holds it (text; None stays None)."""
    return None if value is None else str(value)


def _mm(value):
    return None if value is None else value * 1e3


def _si(value_mm):
    return None if value_mm is None else value_mm * 1e-3


def _pose_dict(f: PoseFigures) -> dict:
    out = {"pose_id": json_label(f.pose_id), "pose": pose_name(f.pose_id), "n": f.n, "ap_mm": f.ap * 1e3,
           **{f"ap_{a}_mm": float(v * 1e3) for a, v in zip("xyz", f.ap_xyz)},
           "rp_mm": _mm(f.rp), "l_mean_mm": _mm(f.l_mean), "s_l_mm": _mm(f.l_std),
           "barycentre_mm": (f.barycentre * 1e3).tolist(), "commanded_mm": (f.commanded * 1e3).tolist()}
    if f.approach is not None:
        out["approach"] = json_label(f.approach)
    if f.ap_abc is not None:
        out.update({f"ap_{a}_deg": float(np.degrees(v)) for a, v in zip("abc", f.ap_abc)})
        out.update({f"rp_{a}_deg": None if f.rp_abc is None else float(np.degrees(f.rp_abc[k]))
                    for k, a in enumerate("abc")})
    return out


def evaluation_dict(result: IsoEvaluation) -> dict:
    """The JSON form of an :class:`~tcr_accuracy.iso9283.evaluate.IsoEvaluation` (mm, deg, s).

    Parameters
    ----------
    result : IsoEvaluation

    Returns
    -------
    dict
    """
    fig = result.figures
    rps = [f.rp for f in fig.poses if f.rp is not None]
    return plain({
        "n_readings": result.n_readings, "n_visits": result.n_visits, "frame": result.frame, "frame_fit": result.how,
        **result.frame_dict(), "standard_cycles": STANDARD_CYCLES,
        "registration": None if result.registration is None else result.registration.to_dict(),
        "poses": [{**_pose_dict(f), **({} if result.instrument_distance is None else
                                       {"instrument_distance_mm": result.instrument_distance[f.pose_id] * 1e3})}
                  for f in fig.poses],
        "summary": {"ap_max_mm": max(f.ap for f in fig.poses) * 1e3,
                    "ap_mean_mm": float(np.mean([f.ap for f in fig.poses])) * 1e3,
                    "rp_max_mm": max(rps) * 1e3 if rps else None},
        "directional": [{"pose_id": json_label(d.pose_id), "approaches": [json_label(a) for a in d.approaches],
                         "vap_mm": d.vap * 1e3,
                         **({} if d.vap_abc is None else
                            {f"vap_{a}_deg": float(np.degrees(v)) for a, v in zip("abc", d.vap_abc)})}
                        for d in fig.directional],
        "distances": [{"pose_a": json_label(d.pose_a), "pose_b": json_label(d.pose_b),
                       **({} if d.approach is None else {"approach": json_label(d.approach)}),
                       "n": d.n, "commanded_mm": d.commanded * 1e3,
                       "mean_mm": d.mean * 1e3, "ad_mm": d.ad * 1e3,
                       **{f"ad_{a}_mm": float(v * 1e3) for a, v in zip("xyz", d.ad_xyz)}, "rd_mm": d.rd * 1e3}
                      for d in fig.distances],
        "stabilisation": [{"pose_id": json_label(s.pose_id),
                           **({} if s.approach is None else {"approach": json_label(s.approach)}),
                           "visits": s.n, "band_mm": s.band * 1e3, "time_mean_s": s.time_mean,
                           "time_max_s": s.time_max, "overshoot_mean_mm": _mm(s.overshoot_mean),
                           "overshoot_max_mm": _mm(s.overshoot_max), "never_entered": s.never_entered}
                          for s in fig.stabilisation],
        "notes": list(fig.notes),
    })


def _angles(doc: dict, prefix: str):
    keys = [f"{prefix}_{a}_deg" for a in "abc"]
    if not all(k in doc for k in keys) or any(doc[k] is None for k in keys):
        return None
    return np.radians([doc[k] for k in keys])


def _pose_figures(doc: dict) -> PoseFigures:
    return PoseFigures(pose_id=_label(doc["pose_id"]), approach=_label(doc.get("approach")), n=int(doc["n"]),
                       commanded=np.asarray(doc.get("commanded_mm", [np.nan] * 3), dtype=float) * 1e-3,
                       barycentre=np.asarray(doc.get("barycentre_mm", [np.nan] * 3), dtype=float) * 1e-3,
                       ap=doc["ap_mm"] * 1e-3, ap_xyz=np.array([doc[f"ap_{a}_mm"] for a in "xyz"]) * 1e-3,
                       rp=_si(doc["rp_mm"]), l_mean=_si(doc.get("l_mean_mm")), l_std=_si(doc.get("s_l_mm")),
                       ap_abc=_angles(doc, "ap"), rp_abc=_angles(doc, "rp"))


def evaluation_from_dict(doc: dict) -> IsoEvaluation:
    """An :class:`~tcr_accuracy.iso9283.evaluate.IsoEvaluation` of its JSON form (:func:`evaluation_dict`).

    The measurement frame's fit stays as the file words it: ``registration`` is None and
    :attr:`IsoEvaluation.how` says how it was fitted; ``pose_q`` and ``orientation_offset`` (not
    in the file) are None.

    Parameters
    ----------
    doc : dict
        A checked document (:func:`tcr_accuracy.read_result`).

    Returns
    -------
    IsoEvaluation
    """
    figures = IsoFigures(
        poses=[_pose_figures(p) for p in doc["poses"]],
        directional=[DirectionalVariation(_label(d["pose_id"]), tuple(map(_label, d.get("approaches", ()))),
                                          d["vap_mm"] * 1e-3, _angles(d, "vap")) for d in doc.get("directional", [])],
        distances=[DistanceFigures(_label(d["pose_a"]), _label(d["pose_b"]), int(d["n"]), d["commanded_mm"] * 1e-3,
                                   d["mean_mm"] * 1e-3, d["ad_mm"] * 1e-3,
                                   np.array([d.get(f"ad_{a}_mm", np.nan) for a in "xyz"]) * 1e-3, d["rd_mm"] * 1e-3,
                                   _label(d.get("approach"))) for d in doc.get("distances", [])],
        notes=list(doc.get("notes", [])),
        stabilisation=[Stabilisation(_label(s["pose_id"]), _label(s.get("approach")), int(s["visits"]),
                                     s["band_mm"] * 1e-3, s.get("time_mean_s"), s.get("time_max_s"),
                                     _si(s.get("overshoot_mean_mm")), _si(s.get("overshoot_max_mm")),
                                     int(s.get("never_entered", 0))) for s in doc.get("stabilisation", [])])
    distances = {p["pose_id"]: p["instrument_distance_mm"] for p in doc["poses"] if "instrument_distance_mm" in p}
    return IsoEvaluation(figures=figures, frame=str(doc.get("frame", "")), registration=None,
                         how=str(doc.get("frame_fit", "")), orientation_offset=None,
                         n_readings=int(doc.get("n_readings", 0)), pose_q=None, n_visits=int(doc.get("n_visits", 0)),
                         frame_source=str(doc.get("frame_source", "base")), absolute=bool(doc.get("ap_absolute", True)),
                         instrument_distance={_label(k): v * 1e-3 for k, v in distances.items()} if distances else None)


@dataclass(frozen=True)
class IsoCondition:
    """One test condition of a pose test: its load and speed (None where not stated), the
    evaluation as measured, and as predicted after compensating with a diagnosis (or None).

    Attributes
    ----------
    load_pct, speed_pct : float or None
        Share of the rated load and speed [%].
    evaluation : IsoEvaluation
    compensated : IsoEvaluation or None
    compensated_with : str
        The diagnosis the compensation was predicted with ("" for none).

    Examples
    --------
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> plan = tcr.plan_iso_cube(robot, np.random.default_rng(0), n_centres=10)
    >>> q = np.tile(plan.q, (10, 1))
    >>> readings = tcr.tcp_poses(robot, q).position + np.random.default_rng(1).normal(0, 1e-5, (50, 3))
    >>> series = tcr.MeasurementSet(joint_names=list(robot.joint_names), q=q, position=readings,
    ...                             annotations={"pose_id": np.array([str(k) for k in range(1, 6)] * 10, dtype=object)})
    >>> result = tcr.IsoTestResult("ur5", "ur5", "tool0", "simulated", (tcr.IsoCondition(
    ...     None, None, tcr.evaluate_pose_test(robot, series, frame="base")),))
    >>> again = tcr.IsoTestResult.from_json(result.to_json())
    >>> len(again.conditions[0].evaluation.figures.poses)
    5
    """

    load_pct: float | None
    speed_pct: float | None
    evaluation: IsoEvaluation
    compensated: IsoEvaluation | None = None
    compensated_with: str = ""

    #: How the compensated figures are obtained, in the file's words.
    COMPENSATED_KIND = "predicted: the model's displacement removed from each reading (first order, positions only)"

    def to_dict(self) -> dict:
        """The condition's JSON form (mm, deg, s)."""
        out = {} if self.load_pct is None and self.speed_pct is None else \
            {"condition": {"load_pct": self.load_pct, "speed_pct": self.speed_pct}}
        out.update(evaluation_dict(self.evaluation))
        if self.compensated is not None:
            out["compensated"] = {"model": self.compensated_with, "kind": self.COMPENSATED_KIND,
                                  **evaluation_dict(self.compensated)}
        return out

    @classmethod
    def from_dict(cls, doc: dict) -> "IsoCondition":
        """Of its JSON form (:meth:`to_dict`)."""
        condition = doc.get("condition") or {}
        compensated = doc.get("compensated")
        return cls(condition.get("load_pct"), condition.get("speed_pct"), evaluation_from_dict(doc),
                   None if compensated is None else evaluation_from_dict(compensated),
                   "" if compensated is None else str(compensated.get("model", "")))


@dataclass(frozen=True)
class IsoTestResult(JsonForm):
    """An ISO 9283 pose test's result: what ``iso9283 evaluate --json`` writes and
    :func:`tcr_accuracy.read_result` reads back.

    Attributes
    ----------
    robot : str
        The robot's name.
    robot_source : str or None
        How to load it again (:attr:`~tcr_accuracy.model.robot.RobotModel.robot_source`).
    tool_frame : str
        Its TCP frame.
    measurements : str
        The pose test's measurement file.
    conditions : tuple of IsoCondition
        Each test condition's figures (one when the file states none).
    document : dict or None
        The JSON form it was read from (None when built from evaluations); :meth:`to_dict`
        gives it back as it was.

    Examples
    --------
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> plan = tcr.plan_iso_cube(robot, np.random.default_rng(0), n_centres=10)
    >>> q = np.tile(plan.q, (10, 1))
    >>> readings = tcr.tcp_poses(robot, q).position + np.random.default_rng(1).normal(0, 1e-5, (50, 3))
    >>> series = tcr.MeasurementSet(joint_names=list(robot.joint_names), q=q, position=readings,
    ...                             annotations={"pose_id": np.array([str(k) for k in range(1, 6)] * 10, dtype=object)})
    >>> result = tcr.IsoTestResult("ur5", "ur5", "tool0", "simulated", (tcr.IsoCondition(
    ...     None, None, tcr.evaluate_pose_test(robot, series, frame="base")),))
    >>> again = tcr.IsoTestResult.from_json(result.to_json())
    >>> len(again.conditions[0].evaluation.figures.poses)
    5
    """

    robot: str
    robot_source: str | None
    tool_frame: str
    measurements: str
    conditions: tuple
    document: dict | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        """The JSON form ``iso9283 evaluate --json`` writes: the first condition's figures at the top
        level and, with several conditions, each under ``conditions``."""
        if self.document is not None:
            return dict(self.document)
        parts = [c.to_dict() for c in self.conditions]
        out = {"measurements": self.measurements, "robot": self.robot, "robot_source": self.robot_source,
               "tool_frame": self.tool_frame, **parts[0]}
        if self.robot_source is None:
            del out["robot_source"]
        if len(parts) > 1:
            out["conditions"] = parts
        return out

    @classmethod
    def from_dict(cls, doc: dict, source: str = "") -> "IsoTestResult":
        """Of its JSON form (a document :func:`tcr_accuracy.read_result` checked).

        Parameters
        ----------
        doc : dict
        source : str
            The file it came from, for messages.

        Returns
        -------
        IsoTestResult
        """
        blocks = doc.get("conditions") or [doc]
        return cls(str(doc["robot"]), doc.get("robot_source"), str(doc.get("tool_frame", "")),
                   str(doc.get("measurements", source)), tuple(IsoCondition.from_dict(b) for b in blocks), doc)

    @classmethod
    def from_json(cls, text: str, source: str = "") -> "IsoTestResult":
        """:meth:`from_dict` of JSON text a script holds (a file: :func:`tcr_accuracy.read_result`).

        Parameters
        ----------
        text : str
        source : str

        Returns
        -------
        IsoTestResult
        """
        from ..exceptions import InputError
        from ..input_files import parse_json

        doc = parse_json(text, source or "ISO 9283 JSON", "give what IsoTestResult.to_json wrote")
        if not isinstance(doc, dict) or not {"robot", "poses", "summary"} <= set(doc):
            raise InputError(f"{source or 'ISO 9283 JSON'}: not an ISO 9283 pose test result")
        return cls.from_dict(doc, source)
