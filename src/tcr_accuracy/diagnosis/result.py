"""What a diagnosis finds: :class:`Diagnosis`, every stage's result and the views of them that
reports, plots and the JSON form read.

:class:`Diagnosis` holds each stage's typed, frozen result (:class:`DiagnosisStages`, SI units
inside) and the figures of the data it ran on; its other attributes are views of those results,
computed when read. :meth:`Diagnosis.to_json` is the JSON form ``diagnose --json`` writes (mm,
unit-suffixed keys; :mod:`tcr_accuracy.diagnosis.result_json`) and :meth:`Diagnosis.from_json`
reads it back: a diagnosis read so gives the same views from the file, and refuses, with
:class:`~tcr_accuracy.exceptions.NotStoredError`, the per-row arrays the file does not hold.
``tcr_accuracy.diagnosis_summary(diagnosis)`` is the printed summary.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ..effects import make_effect, predict_positions
from ..exceptions import InputError, NotStoredError
from ..io.json_values import JsonForm
from ..model.context import MeasurementContext
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel
from .records import ErrorStats, Step
from .result_json import NOT_STORED, STORED_VIEWS, diagnosis_document
from .stages.attribute import Attribution, FirstOrder
from .stages.parameters import FittedParameters
from .stages.register import RegisteredMeasurements
from .stages.residual import ResidualAnalysis
from .stages.select import Selection
from .stages.setup import SessionSetup
from .stages.candidates import CandidateSet

__all__ = ["Diagnosis", "DiagnosisStages", "ErrorStats", "Step"]


def _leave_one_out(stages) -> list:
    """Stage 3's leave-one-out refits with stage 4's own share of each effect (JSON form, mm)."""
    own = stages.attribute.own_shares
    return [{**r.to_dict(), **({"own_share_increase_mm": own[r.effect][0] * 1e3,
                                "own_share_interval_mm": [own[r.effect][1] * 1e3, own[r.effect][2] * 1e3]}
                               if r.effect in own else {})}
            for r in stages.select.leave_one_out]


@dataclass(frozen=True)
class DiagnosisStages:
    """Every stage's result, in the order they ran (see :mod:`tcr_accuracy.diagnosis.stages`)."""

    register: RegisteredMeasurements
    candidates: CandidateSet
    select: Selection
    attribute: Attribution
    residual: ResidualAnalysis
    parameters: FittedParameters
    first_order: FirstOrder
    setup: SessionSetup | None = None


@dataclass(frozen=True, repr=False, eq=False)
class Diagnosis(JsonForm):
    """Everything :func:`~tcr_accuracy.diagnosis.diagnose.diagnose` found. Lengths in m inside;
    :meth:`to_json` writes the JSON form ``diagnose --json`` writes (mm), :meth:`from_json`
    reads it back.

    A fitted diagnosis holds the stages' results in :attr:`stages` (typed, SI). The other
    attributes are read-only views of them: numbers and arrays in SI (``gap``, ``steps``,
    ``noise_floor``, ``tracker_noise``, the residuals in m), and the JSON-form dicts the
    reports read, whose keys carry their unit (``where_mm``, ``candidates``, ``leave_one_out``,
    ``scatter``, ``structure``, ``sessions``, ``drift``: ``rms_mm``, ``gain_mm``).

    A diagnosis read from its JSON form (:meth:`from_json`, :func:`tcr_accuracy.read_result`)
    has no stages: each view is read from the file, equal to the fitted one to the rounding of
    its mm figures (a few parts in 1e16); what the file does not hold (:data:`NOT_STORED_VIEWS`: the
    per-row residuals, joint values and gravity torques, the semivariograms, the stages) raises
    :class:`~tcr_accuracy.exceptions.NotStoredError` naming it.

    Arrays of the residual (``gap_residual``, ``final_residual``, ``heldout_residual``), ``q``
    and ``nominal_position`` are those of the first measured frame; with several,
    ``frames_measured`` names them and ``heldout_by_frame`` gives each one's figures.

    Attributes
    ----------
    robot_name : str
    n_measurements : int
    folds : int
        k of the k-fold cross-validation.
    stages : DiagnosisStages or None
        The stages' results (None for a diagnosis read from its JSON form).
    n_fits : int
        Least-squares fits the diagnosis ran.
    joint_names : list of str
        The robot's joints, in q's column order.
    source : str
        Where the measurements came from (file names).
    document : dict or None
        The JSON form it was read from (None for a fitted diagnosis).
    file : str
        The file it was read from ("" for a fitted diagnosis or one read from text).

    Examples
    --------
    >>> import pathlib
    >>> import tempfile
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> fitted = tcr.diagnose(robot, measured, effects=["joint_offsets", "compliance"], folds=3)
    >>> path = tempfile.mkdtemp() + "/diagnosis.json"
    >>> _ = pathlib.Path(path).write_text(fitted.to_json())
    >>> loaded = tcr.read_result(path)
    >>> loaded.steps[-1].heldout.rms == fitted.steps[-1].heldout.rms, loaded.from_file
    (True, True)
    """

    robot_name: str
    n_measurements: int
    folds: int
    stages: DiagnosisStages | None
    n_fits: int
    joint_names: list
    source: str = ""
    document: dict | None = None
    file: str = ""
    _stored: dict = field(default_factory=dict, init=False, repr=False)

    # -- reading a view: from the stages, or from the file --------------------------------
    def _view(self, name: str, of_stages):
        """The view ``name``: ``of_stages(self.stages)`` of a fitted diagnosis, else read from its
        JSON form (:data:`~tcr_accuracy.diagnosis.result_json.STORED_VIEWS`), once."""
        if self.stages is not None:
            return of_stages(self.stages)
        if name not in self._stored:
            if name in NOT_STORED:
                raise NotStoredError(f"{name}: a diagnosis read from {self.file or 'its JSON form'} does not hold "
                                     f"{NOT_STORED[name]}; run the diagnosis on the measurements to have it", name)
            try:
                self._stored[name] = STORED_VIEWS[name](self.document)
            except KeyError as missing:
                raise NotStoredError(f"{name}: {self.file or 'the JSON form'} has no key {missing}; written by an "
                                     "older tcr-accuracy, or not by Diagnosis.to_json", name) from None
        return self._stored[name]

    @property
    def from_file(self) -> bool:
        """True for a diagnosis read from its JSON form (no stages, no per-row arrays)."""
        return self.stages is None

    # -- views of the stages -------------------------------------------------------------
    @property
    def gap(self) -> ErrorStats:
        """Errors after fitting the frames [m]."""
        return self._view("gap", lambda s: s.residual.gap)

    @property
    def where_mm(self) -> dict:
        """Where the gap lies (JSON form, keys suffixed with their unit, mostly _mm)."""
        return self._view("where_mm", lambda s: s.residual.where_mm)

    @property
    def where(self) -> dict:
        """Deprecated alias of :attr:`where_mm` (until 0.2): the name now says its unit."""
        return self.where_mm

    @property
    def identifiability(self) -> dict:
        return self._view("identifiability", lambda s: s.parameters.identifiability)

    @property
    def candidates(self) -> dict:
        """effect -> first-step held-out result or why it was not tried (JSON form)."""
        return self._view("candidates", lambda s: {c.effect: c.to_dict() for c in s.select.candidates})

    @property
    def steps(self) -> list:
        """The shrink table (:class:`Step`, SI) in the order the effects explain the data."""
        return self._view("steps", lambda s: list(s.attribute.steps))

    @property
    def selected_effects(self) -> list:
        return self._view("selected_effects", lambda s: list(s.select.selected))

    @property
    def primary_effect(self) -> str | None:
        return self._view("primary_effect", lambda s: s.attribute.primary_effect)

    @property
    def primary_group(self) -> list:
        """The primary effect and what stands in for it."""
        return self._view("primary_group", lambda s: list(s.attribute.primary_group))

    @property
    def primary_tied(self) -> list:
        """The largest own share and those not ranked below it."""
        return self._view("primary_tied", lambda s: list(s.attribute.primary_tied))

    @property
    def leave_one_out(self) -> list:
        """The final model without each chosen effect (JSON form, mm): the others refitted, and held to
        their own parameters (its own share, with stage 4's 95 % interval)."""
        return self._view("leave_one_out", _leave_one_out)

    @property
    def eliminated(self) -> list:
        return self._view("eliminated", lambda s: [e.to_dict() for e in s.select.eliminated])

    @property
    def swaps(self) -> list:
        """One-standard-error swaps made after forward selection."""
        return self._view("swaps", lambda s: list(s.select.swaps))

    @property
    def search(self) -> dict:
        """The search beyond the greedy path: sets fitted, where each path ended, the best set on
        another path and whether the chosen set beats it by more than a standard error."""
        return self._view("search", lambda s: s.select.search.to_dict())

    @property
    def ambiguous(self) -> list:
        """Groups of effects the data cannot tell apart."""
        return self._view("ambiguous", lambda s: list(s.select.ambiguous))

    @property
    def noise(self):
        """The instrument's per-axis noise [m] and where that figure came from (NoiseEstimate)."""
        return self._view("noise", lambda s: s.residual.noise)

    @property
    def noise_floor(self) -> float:
        """RMS norm of the measurement noise [m]."""
        return self._view("noise_floor", lambda s: s.residual.noise_floor)

    @property
    def tracker_noise(self) -> float:
        """Per-axis standard deviation of the measurement noise [m]."""
        return self._view("tracker_noise", lambda s: s.residual.noise.per_axis)

    @property
    def fold_assignments(self) -> int | None:
        """How many k-fold assignments the held-out figures pool (None: not said by an older file)."""
        if self.stages is None and "fold_assignments" not in self.document:
            return None
        return self._view("fold_assignments", lambda s: len(s.residual.heldout_repeats))

    @property
    def scatter(self) -> dict:
        return self._view("scatter", lambda s: s.residual.scatter)

    @property
    def structure(self) -> dict:
        return self._view("structure", lambda s: s.residual.structure)

    @property
    def parameters(self) -> dict:
        """effect -> {name: value SI} (identifiable parameters)."""
        return self._view("parameters", lambda s: s.parameters.values)

    @property
    def parameter_units(self) -> dict:
        return self._view("parameter_units", lambda s: s.parameters.units)

    @property
    def parameter_table(self) -> dict:
        """effect -> values, std, interval, range, fit_range, pinned [SI] by parameter name."""
        return self._view("parameter_table", lambda s: s.parameters.table)

    @property
    def effect_parameters(self) -> dict:
        """effect -> full (k,) vector [SI], first measured frame."""
        return self._view("effect_parameters", lambda s: s.parameters.full_vectors)

    @property
    def effect_options(self) -> dict:
        return self._view("effect_options", lambda s: s.parameters.effect_options)

    @property
    def physics(self) -> dict:
        """effect -> why its parameters lie in their range."""
        return self._view("physics", lambda s: s.parameters.physics)

    @property
    def joint_function_bands(self) -> dict:
        """effect -> joint -> {"angle_rad", "value_rad", "std_rad"} (M,) arrays: the fitted
        function of each joint's own angle with its standard error (effects with joint_basis)."""
        return self._view("joint_function_bands", lambda s: s.parameters.joint_function_bands)

    @property
    def as_built_x(self) -> np.ndarray:
        return self._view("as_built_x", lambda s: s.parameters.as_built_x)

    @property
    def trackerMbase(self) -> np.ndarray:
        """(4, 4) the robot's base in the tracker frame, fitted base twist included
        (``p_tracker = trackerMbase @ p_base``)."""
        return self._view("trackerMbase", lambda s: s.parameters.trackerMbase)

    @property
    def tracker_transform(self) -> np.ndarray:
        """Deprecated alias of :attr:`trackerMbase` (until 0.2): one name for the base-to-tracker transform."""
        warnings.warn("Diagnosis.tracker_transform is deprecated and will be removed in 0.2; use "
                      "Diagnosis.trackerMbase", DeprecationWarning, stacklevel=2)
        return self.trackerMbase

    @property
    def registration(self) -> tuple:
        """(R, t) the first session's closed-form tracker frame (before the fitted base twist):
        tracker = R robot + t. The fitted transform is :attr:`trackerMbase`."""
        return self._view("registration", lambda s: s.register.stations[0])

    @property
    def final_residual(self) -> np.ndarray:
        """(N, 3) in-sample residual of the final model [m]."""
        return self._view("final_residual", lambda s: s.residual.final_residual)

    @property
    def heldout_residual(self) -> np.ndarray:
        """(N, 3) out-of-fold residual of the final model [m]."""
        return self._view("heldout_residual", lambda s: s.residual.heldout_residual)

    @property
    def gap_residual(self) -> np.ndarray:
        """(N, 3) residual after frames only [m]."""
        return self._view("gap_residual", lambda s: s.residual.gap_residual)

    @property
    def semivariograms(self) -> list:
        return self._view("semivariograms", lambda s: s.residual.semivariograms)

    @property
    def q(self) -> np.ndarray:
        return self._view("q", lambda s: s.register.measurements.q)

    @property
    def nominal_position(self) -> np.ndarray:
        return self._view("nominal_position", lambda s: s.register.nominal[0].position)

    @property
    def gravity_torque(self) -> np.ndarray:
        return self._view("gravity_torque", lambda s: s.register.gravity_torque)

    @property
    def frames_measured(self) -> list:
        return self._view("frames_measured", lambda s: [p.label for p in s.register.parts])

    @property
    def heldout_by_frame(self) -> dict:
        return self._view("heldout_by_frame", lambda s: s.residual.heldout_by_frame)

    @property
    def orientation(self) -> dict:
        o = self._view("orientation", lambda s: s.residual.orientation)
        return {} if o is None else o if isinstance(o, dict) else o.to_dict()

    @property
    def sessions(self) -> list:
        """Per session: label, rows, gap and held-out stats, temperature (JSON form)."""
        return self._view("sessions", lambda s: [x.to_dict() for x in s.residual.sessions])

    @property
    def session_setup(self) -> dict | None:
        """What each session owns (a tracker frame, a TCP offset, both or neither), the setups
        compared and each session's sizes (JSON form, :mod:`~tcr_accuracy.diagnosis.stages.setup`);
        None for one session."""
        return self._view("session_setup", lambda s: None if s.setup is None else s.setup.to_dict())

    @property
    def drift(self) -> list:
        """Per session: the tracker's drift seen by base references (JSON form)."""
        return self._view("drift", lambda s: list(s.register.drift))

    @property
    def selection(self) -> dict:
        """How often each effect is chosen over bootstrap replays."""
        return self._view("selection", lambda s: s.attribute.stability)

    @property
    def mechanisms(self) -> list:
        """For every chosen effect, the mechanism its fitted sign and size fit (JSON form)."""
        return self._view("mechanisms", lambda s: [m.to_dict() for m in s.attribute.mechanisms])

    @property
    def families(self) -> list:
        """Every family with a chosen effect and its share, largest first (JSON form, mm)."""
        return self._view("families", lambda s: [f.to_dict() for f in s.attribute.families])

    @property
    def own_share_ranking(self) -> list:
        """The largest own share against each other the primary effect was chosen among: the
        difference, its 95 % interval (paired, the same bootstrap replicates) and whether the held-out
        rows rank the two apart (JSON form, mm; the families' are in :attr:`families`, ``below_largest``)."""
        return self._view("own_share_ranking", lambda s: [c.to_dict() for c in s.attribute.own_share_ranking])

    @property
    def interval_method(self) -> str:
        """How the shares' 95 % intervals were computed, in words."""
        return self._view("interval_method", lambda s: s.attribute.interval_method)

    @property
    def primary_family(self) -> str | None:
        """The family with the largest share, when the held-out rows rank it above the others."""
        return self._view("primary_family", lambda s: s.attribute.primary_family)

    @property
    def outside_physics(self) -> list:
        """The chosen effects whose fitted values another mechanism than their own physics explains
        (a controller's compensation, the instrument), with its words."""
        return self._view("outside_physics", lambda s: [
            {"effect": m.effect, "description": m.mechanism, "physical": m.physical,
             "n_outside": sum(1 for p in m.parameters if not p["textbook"])}
            for m in s.attribute.mechanisms if not m.textbook and m.effect != "frames"])

    @property
    def confounding(self) -> list:
        """Effects that follow the order of measurement, and why (JSON form)."""
        return self._view("confounding", lambda s: [c.to_dict() for c in s.attribute.confounding])

    @property
    def instrument(self) -> dict | None:
        """The measuring instrument's specification the diagnosis weighed the points by (JSON form), or None."""
        return self._view("instrument", lambda s: None if s.register.instrument is None
                          else s.register.instrument.to_dict())

    @property
    def geometry_checks(self) -> list:
        """The fitted geometry against what the robot's class allows (axis tilts, the tool frame's
        displacement and rotation, the fitted TCP offset against a given one), JSON form (mm, deg)."""
        return self._view("geometry_checks", lambda s: [c.to_dict() for c in s.parameters.geometry_checks])

    @property
    def geometry_tolerance(self) -> dict | None:
        """The tolerances of the robot's class the geometry is held to (JSON form, mm, deg), or None."""
        return self._view("geometry_tolerance", lambda s: None if s.parameters.tolerance is None
                          else s.parameters.tolerance.to_dict())

    @property
    def contribution(self) -> dict:
        """effect -> RMS TCP motion of its fit beyond frames [m]."""
        return self._view("contribution", lambda s: s.first_order.contribution)

    @property
    def second_order(self) -> dict:
        """What one fixed-point step of the deflections adds (JSON form)."""
        return self._view("second_order", lambda s: s.first_order.to_dict())

    @property
    def notes(self) -> list:
        """Every stage's notes, in the order the stages found them."""
        return self._view("notes", lambda s: [
            *s.register.notes, *s.candidates.notes, *s.select.notes, *s.attribute.notes,
            *s.select.decision_notes(), *s.residual.notes, *s.parameters.notes, *s.first_order.notes])

    @property
    def structure_remains(self) -> bool:
        return bool(self.structure.get("remains", False))

    def __repr__(self) -> str:
        last = self.steps[-1].heldout.rms if self.steps else float("nan")
        return (f"Diagnosis({self.robot_name!r}, {self.n_measurements} measurements, "
                f"gap RMS {self.gap.rms * 1e3:.4g} mm, selected [{', '.join(self.selected_effects)}], "
                f"primary {self.primary_effect!r}, held-out RMS {last * 1e3:.4g} mm, "
                f"noise floor {self.noise_floor * 1e3:.4g} mm" + (", read from file)" if self.from_file else ")"))

    # -- what the fitted model predicts ---------------------------------------------------
    def model_positions(self, robot: RobotModel, q, context: MeasurementContext | None = None) -> np.ndarray:
        """(N, 3) TCP positions [m] of the fitted model at joints q (N, n_joints) [rad, m], in the
        robot's base frame as fitted (the base twist of ``frames`` belongs to :attr:`trackerMbase`),
        at the rows' context (payload, temperature, ...; None: the defaults); the first measured
        frame's robot."""
        vectors, effects = [], []
        for e, vector in self.effect_parameters.items():
            effect = make_effect(e, robot, **self.effect_options.get(e, {}))
            names = effect.parameter_names()
            if len(names) != len(vector):
                raise InputError(f"{e}: the diagnosis has {len(vector)} parameters, {robot.name}'s {e} has "
                                 f"{len(names)}: predict with the robot it was fitted to", parameter="robot")
            vector = np.array(vector, dtype=float)
            if e == "frames":  # the base twist is the tracker's: trackerMbase holds it
                vector[[k for k, n in enumerate(names) if n.startswith("frames.base.")]] = 0.0
            effects.append(effect)
            vectors.append(vector)
        return predict_positions(robot, effects, vectors, np.atleast_2d(np.asarray(q, dtype=float)), context)

    def predict(self, robot: RobotModel, q, context: MeasurementContext | None = None) -> np.ndarray:
        """(N, 3) TCP position errors [m] the fitted model predicts at joints q (N, n_joints),
        in the robot's base frame: the fitted model's TCP minus the nominal robot's (what every
        estimator's ``predict`` gives: :func:`tcr_accuracy.make_predictor`, :class:`GapDiagnosis`).

        Parameters
        ----------
        robot : RobotModel
            The robot it was fitted to (the first measured frame's).
        q : array-like of shape (N, n_joints)
            Commanded joint values [rad, m].
        context : MeasurementContext, optional
            The rows' payload, temperature, ... (None: the defaults).

        Returns
        -------
        ndarray of shape (N, 3)
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return self.model_positions(robot, q, context) - tcp_poses(robot, q).position

    def tracker_positions(self, robot: RobotModel, q, context: MeasurementContext | None = None) -> np.ndarray:
        """(N, 3) TCP positions [m] in the tracker frame the fitted model predicts at joints q
        (N, n_joints): :meth:`model_positions` mapped by :attr:`trackerMbase` (what the tracker
        measures)."""
        m = self.trackerMbase
        return self.model_positions(robot, q, context) @ m[:3, :3].T + m[:3, 3]

    # -- the JSON form --------------------------------------------------------------------
    def to_dict(self, robot: RobotModel | None = None) -> dict:
        """The JSON form ``diagnose --json`` writes: plain JSON values (an unbounded side null),
        mm for lengths with ``_mm`` keys, SI for the parameters, ``trackerMbase``, and
        ``effect_parameters`` (every effect's full parameter vector by name [SI], what ``export``
        rebuilds the model from). A diagnosis read from a file gives back that file's document.

        Parameters
        ----------
        robot : RobotModel, optional
            Not needed (the stages know the robot); accepted for scripts of 0.1.

        Returns
        -------
        dict
        """
        if self.stages is None:
            return dict(self.document)
        return diagnosis_document(self)

    @classmethod
    def from_dict(cls, document: dict, source: str = "") -> "Diagnosis":
        """A diagnosis of its JSON form (a document :func:`tcr_accuracy.read_result` checked whole:
        schema, figures against each other, one copy of each number); its views read from it.

        Parameters
        ----------
        document : dict
            The JSON form (:meth:`to_dict`, ``diagnose --json``).
        source : str
            The file it came from (:attr:`file`), named in messages.

        Returns
        -------
        Diagnosis
        """
        n_fits = document.get("n_fits", 0)
        d = cls(robot_name=str(document["robot"]), n_measurements=int(document.get("n_measurements", 0)),
                folds=int(document.get("folds", 0)), stages=None, n_fits=int(n_fits) if n_fits else 0,
                joint_names=[], source=str(document.get("measurements", "")), document=document, file=str(source))
        try:
            names = d._view("joint_names", None)
        except NotStoredError:
            names = []
        d.joint_names.extend(names)
        return d

    @classmethod
    def from_json(cls, text: str, source: str = "diagnosis JSON") -> "Diagnosis":
        """:meth:`from_dict` of JSON text (what :meth:`to_json` gave). A file is read with
        :func:`tcr_accuracy.read_result`, the one reader of result files, which checks it whole
        (schema, figures against each other, one copy of each number, the robot against its source)
        before it builds the diagnosis; this reads text a script holds and checks only that it is a
        diagnosis' JSON form.

        Parameters
        ----------
        text : str
            What :meth:`to_json` or ``diagnose --json`` wrote.
        source : str, default="diagnosis JSON"
            Named in messages.

        Returns
        -------
        Diagnosis
        """
        from ..input_files import parse_json

        document = parse_json(text, source, "give what Diagnosis.to_json wrote")
        if not isinstance(document, dict) or not {"robot", "steps", "parameters"} <= set(document):
            raise InputError(f"{source}: not a diagnosis as Diagnosis.to_json writes it")
        return cls.from_dict(document, source)


#: What a diagnosis read from its JSON form does not hold (:class:`~tcr_accuracy.exceptions.NotStoredError`).
NOT_STORED_VIEWS = tuple(NOT_STORED)
