"""Sim-to-real gap diagnosis: how big the gap is, where it lies, which unmodelled effect
causes it, and how far it shrinks once that effect is in the model.

The input is a set of measurements of the real robot (commanded joint values, the
position, and optionally orientation, of one or more measured frames in the tracker's
own frame, optional context); the nominal model is a
:class:`~tcr_accuracy.model.robot.RobotModel` per measured frame. Steps:

1. **Gap.** The tracker frame is registered to the robot's base (closed-form Kabsch on
   nominal vs measured positions), then the ``frames`` effect (base twist and TCP
   offsets) is fitted; the remaining error is the gap.
2. **Where.** That residual per axis, per workspace region, against each joint value,
   gravity torque, payload, temperature and approach direction, and along which joints
   it varies (:func:`~tcr_accuracy.diagnosis.residuals.where_analysis`).
3. **Which effect.** Every effect of the vocabulary (:mod:`tcr_accuracy.effects`) is a
   parametric model on top of the nominal kinematics, fitted by the engine of
   :mod:`tcr_accuracy.diagnosis.fitting`; identifiability per candidate model
   (:mod:`tcr_accuracy.diagnosis.identifiability`): a parameter whose own part moves the TCP less
   than a tenth of the noise is named and removed with what it duplicates. Effects
   enter by forward selection on k-fold held-out error when a one-sided paired test on
   the per-measurement held-out squared errors gives z > ``selection_z``. Identifiability
   is then re-judged at the fitted sizes (an effect fitted at 13x its typical size
   resolves columns 13x smaller). Forward selection is greedy: every chosen effect is
   swapped for every unchosen one (:mod:`tcr_accuracy.diagnosis.ambiguity`); where the
   data cannot tell them apart, the one-standard-error rule keeps the one with fewer
   parameters, and the group is reported. Backward elimination drops a chosen effect
   that the others can replace (same test).
4. **How far it shrinks.** Held-out mean/RMS/max after each step; a leave-one-out table
   over the chosen set, two ways: with the others refitted and free to take the dropped
   effect's place (what backward elimination uses), and with the others held to the
   parameters they have in the final model (the dropped effect's *own share*, under the
   vocabulary's convention that an earlier effect keeps what a later one duplicates);
   the **primary effect** is the one with the largest own share, named only when nothing
   stands in for it (else the answer is its ambiguity group). Then the final residual
   next to the noise floor, whether structure remains in joint space, whether the test
   had the power to see a leftover of the size left (else "cannot tell"), whether there
   is scatter beyond the instrument's (:mod:`tcr_accuracy.diagnosis.structure`), and
   whether the deflections are small enough for the first-order effect models.

The noise is not assumed: without ``tracker_noise`` it comes from repeated poses, else
from the final residual (:func:`~tcr_accuracy.diagnosis.residuals.noise_from_residual`), and the
result says which.

All lengths are SI (m) inside; :meth:`Diagnosis.to_dict` converts to mm with unit
suffixed keys. Nothing here prints or plots.
"""

from __future__ import annotations

import dataclasses
import warnings
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils._param_validation import Interval

from ..effects import vocabulary
from ..exceptions import AnalysisError, InputError
from ..hyperparameters import validate_hyperparameters
from ..io.measurements import MeasurementSet
from ..model.context import MeasurementContext
from ..model.robot import RobotModel
from ..random_state import int_seed, renamed_keyword
from .bases import ordered
from .paired import paired_z
from .records import ErrorStats, Step
from .result import Diagnosis, DiagnosisStages
from .stages.attribute import attribute_effects, first_order_reach
from .stages.candidates import build_candidates
from .stages.parameters import collect_parameters
from .stages.register import MeasuredFrame, register_measurements
from .stages.residual import analyse_residual
from .stages.select import select_effects
from .stages.setup import compare_setups


# ---------------------------------------------------------------------------------------
# The diagnosis
# ---------------------------------------------------------------------------------------
@renamed_keyword("seed", "random_state")
def diagnose(robot: RobotModel, measurements, *, effects=None, folds: int = 5, random_state=0,
             tracker_noise: float | None = None, selection_z: float = 3.0, min_relative_gain: float = 0.002,
             rank_tol: float = 1e-6, orientation_weight: float | None = None, progress=None,
             references=(), instrument=None, tcp_offset=None) -> Diagnosis:
    """Diagnose the gap between the nominal robot and its measurements.

    The function form of :class:`GapDiagnosis`: ``GapDiagnosis(robot=robot, ...).fit(measurements).result_``.

    Parameters
    ----------
    robot : RobotModel
        The nominal model (of the measured frame).
    measurements : MeasurementSet, or list of (RobotModel, MeasurementSet)
        q (N, n_joints) [rad, m], position (N, 3) [m] in the tracker frame, context. A
        list measures several frames on the same rows (each with the robot whose TCP it
        is; ``robot`` is then the first one's): their shared parameters are fitted once.
    effects : list of str, default=None
        Effects to consider (vocabulary order is used; ``frames`` is always in). None: the
        whole vocabulary.
    folds : int, default=5
        k of the k-fold cross-validation (>= 2).
    random_state : int, numpy.random.Generator or None, default=0
        Seeds the fold split, the permutation tests and the bootstrap replays (formerly
        ``seed``, still accepted with a DeprecationWarning).
    tracker_noise : float, default=None
        Per-axis standard deviation of the instrument [m]; noise floor = sqrt(3) times it.
        None: estimated from the data (repeated poses, else the final residual).
    selection_z : float, default=3.0
        One-sided z the paired held-out test must exceed for an effect to enter.
    min_relative_gain : float, default=0.002
        And the held-out RMS must drop by at least this fraction.
    rank_tol : float, default=1e-6
        Identifiability tolerance on normalised pivots.
    orientation_weight : float, default=None
        [m/rad] weight of measured orientation in the fit (an angle counts as the position
        error it makes at this distance); None: the RMS spread of the measured points
        about their centre.
    progress : callable(str), default=None
        Called with a short message as the work advances (the CLI's progress bar).
    instrument : Instrument, default=None
        The measuring instrument's specification: per-point weights, and the noise floor where
        the data's redundancy gives none (see :class:`GapDiagnosis`).
    references : list of (frame, position (3,) [m], measured (N, 3) [m], time_s (N,) or None), default=()
        Base references: frames fixed to the robot's base (their place in the base frame), measured on
        the same rows in the tracker frame: they pin the tracker frame and show its drift
        (estimated per session, corrected where significant and larger than the noise).
    tcp_offset : array-like of shape (3,), default=None
        The measured point's offset from the robot's tool frame as the user knows it [m] (see
        :class:`GapDiagnosis`).

    Returns
    -------
    Diagnosis
        Everything found, SI units; ``print(tcr_accuracy.diagnosis_summary(result))`` prints what the command line does.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets", "compliance"], folds=3)
    >>> d.primary_effect, round(d.steps[-1].heldout.rms * 1e3, 2)  # [mm]
    ('compliance', 0.3)
    """
    return GapDiagnosis(robot=robot, effects=effects, folds=folds, random_state=random_state,
                        tracker_noise=tracker_noise, selection_z=selection_z, min_relative_gain=min_relative_gain,
                        rank_tol=rank_tol, orientation_weight=orientation_weight, instrument=instrument,
                        tcp_offset=tcp_offset).fit(
        measurements, progress=progress, references=references).result_


def _one_blas_thread():
    """The least-squares problems here are small (3N x ~60): multi-threaded BLAS only adds
    synchronisation, and on a shared machine it was 50-100x slower than one thread.
    threadpoolctl (a scikit-learn dependency) limits it for the duration of a call."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


class GapDiagnosis(BaseEstimator):
    """The diagnosis as a scikit-learn estimator: hyper-parameters here, ``fit`` does the work.

    ``fit`` takes a :class:`~tcr_accuracy.io.measurements.MeasurementSet`, not ``(X, y)``
    arrays: besides joint values (X) and measured positions (y) the diagnosis needs each
    row's context (payload, temperature, approach direction, session, other joints),
    measured orientation when there is one, and, for several measured frames, one robot
    per frame; a MeasurementSet carries them together, row-aligned. The nominal robot is a
    constructor parameter so that ``sklearn.base.clone`` gives an unfitted copy that fits
    the same data to the same numbers.

    Parameters
    ----------
    robot : RobotModel, default=None
        The nominal model of the measured frame (required by :meth:`fit`; with a list of
        (robot, measurements) pairs the first pair's robot is used).
    effects : list of str, default=None
        Effects to consider; None: the whole vocabulary (``frames`` is always in).
    folds : int, default=5
        k of the k-fold cross-validation (>= 2).
    random_state : int, numpy.random.Generator or None, default=0
        Seeds the fold split, the permutation tests and the bootstrap replays; an int gives
        the same result every time (formerly ``seed``).
    tracker_noise : float, default=None
        Per-axis standard deviation of the instrument [m]; None: estimated from the data.
    selection_z : float, default=3.0
        One-sided z the paired held-out test must exceed for an effect to enter.
    min_relative_gain : float, default=0.002
        And the held-out RMS must drop by at least this fraction.
    rank_tol : float, default=1e-6
        Identifiability tolerance on normalised pivots.
    orientation_weight : float, default=None
        [m/rad] weight of measured orientation; None: the measured points' RMS spread.
    stability_replays : int, default=50
        Bootstrap replays of the selection that give each effect's selection frequency (at least 1:
        a frequency needs a replay).
    fold_repeats : int or None, default=None
        Fold assignments of the repeated k-fold cross-validation: every held-out figure and
        test is over all of them, so that the answer does not hang on one split of the rows.
        None: 5 up to 2,000 measurements, fewer above (one from 10,000), where one split
        already decides the same way.
    instrument : Instrument, default=None
        The measuring instrument's specification (:data:`tcr_accuracy.frames.instrument.INSTRUMENTS`
        or :func:`~tcr_accuracy.frames.instrument.instrument_from`): every measured point weighed
        by its own noise (an MPE growing with its distance, along and across the beam), and the
        noise floor from it where the data's redundancy gives none. None: every point alike.
    tcp_offset : array-like of shape (3,), default=None
        The measured point's offset from the robot's tool frame (of the first measured frame), in that
        frame's axes, as the user knows it (a drawing, the tool's data sheet) [m]. The diagnosis fits
        its own; the two are set side by side and flagged where they differ by more than the robot's
        class allows (:mod:`tcr_accuracy.diagnosis.plausibility`). None: not checked.

    Attributes
    ----------
    result_ : Diagnosis
        Everything found (SI units); ``tcr_accuracy.diagnosis_summary(result_)`` is the printed summary.
    robot_ : RobotModel
        The robot the diagnosis ran on.
    selected_effects_ : list of str
        The effects chosen (``frames`` first).
    primary_effect_ : str or None
        The effect with the largest own share, None when others stand in for it.
    parameters_ : dict
        Effect -> {parameter name: fitted value [SI]}.
    noise_ : NoiseEstimate
        The instrument's noise per axis [m] and where that figure came from.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> estimator = tcr.GapDiagnosis(robot=robot, effects=["joint_offsets", "compliance"], folds=3, random_state=0)
    >>> estimator.get_params()["folds"]
    3
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> estimator.fit(measured).selected_effects_
    ['frames', 'compliance', 'joint_offsets']
    >>> estimator.predict(measured.q[:2]).shape  # TCP position errors, base frame [m]
    (2, 3)
    """

    #: checked when fit starts (:func:`tcr_accuracy.hyperparameters.validate_hyperparameters`)
    _parameter_constraints = {
        "folds": [Interval(Integral, 2, None, closed="left")],
        "tracker_noise": [None, Interval(Real, 0, 1, closed="right")],
        "selection_z": [Interval(Real, 0, 100, closed="neither")],
        "min_relative_gain": [Interval(Real, 0, 1, closed="left")],
        "rank_tol": [Interval(Real, 0, 1, closed="neither")],
        "orientation_weight": [None, Interval(Real, 0, 1e3, closed="neither")],
        "stability_replays": [Interval(Integral, 1, 100_000, closed="both")],
        "fold_repeats": [None, Interval(Integral, 1, 1000, closed="both")],
        "tcp_offset": [None, "array-like"],
    }

    @renamed_keyword("seed", "random_state")
    def __init__(self, *, robot=None, effects=None, folds: int = 5, random_state=0,
                 tracker_noise: float | None = None, selection_z: float = 3.0, min_relative_gain: float = 0.002,
                 rank_tol: float = 1e-6, orientation_weight: float | None = None, stability_replays: int = 50,
                 fold_repeats: int | None = None, instrument=None, tcp_offset=None):
        self.robot = robot
        self.effects = effects
        self.folds = folds
        self.random_state = random_state
        self.tracker_noise = tracker_noise
        self.selection_z = selection_z
        self.min_relative_gain = min_relative_gain
        self.rank_tol = rank_tol
        self.orientation_weight = orientation_weight
        self.stability_replays = stability_replays
        self.fold_repeats = fold_repeats
        self.instrument = instrument
        self.tcp_offset = tcp_offset

    def __repr__(self, N_CHAR_MAX=700) -> str:
        """scikit-learn's repr of the parameters on one line, and once fitted what was found."""
        text = " ".join(super().__repr__(N_CHAR_MAX).split())
        if hasattr(self, "result_"):
            d = self.result_
            text += (f" fitted: selected [{', '.join(d.selected_effects)}], "
                     f"held-out RMS {d.steps[-1].heldout.rms * 1e3:.4g} mm")
        return text

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.non_deterministic = self.random_state is None
        return tags

    # -- inputs ------------------------------------------------------------------------
    def _check(self, robot, measurements) -> list[MeasuredFrame]:
        if isinstance(measurements, (list, tuple)):
            frames = [MeasuredFrame(r, _measurement_set(m), r.tool_frame) for r, m in measurements]
        else:
            frames = [MeasuredFrame(robot, _measurement_set(measurements), robot.tool_frame)]
        if self.folds < 2:
            raise InputError(f"folds={self.folds}: need at least 2", parameter="folds", value=self.folds)
        n = len(frames[0].measurements)
        for f in frames:
            q = f.measurements.q
            if q.ndim != 2 or q.shape[1] != f.robot.n_joints:
                raise InputError(f"measurements have {q.shape[-1]} joint columns, {f.robot.name} has "
                                 f"{f.robot.n_joints}")
            if len(f.measurements) != n:
                raise InputError(f"measured frame {f.label}: {len(f.measurements)} rows, the first frame has {n}")
        if n < max(3 * self.folds, 12):
            raise InputError(f"{n} measurements are too few to diagnose with {self.folds}-fold cross-validation "
                             f"(need at least {max(3 * self.folds, 12)})")
        words = vocabulary()
        if self.effects is not None:
            unknown = [e for e in self.effects if e not in words]
            if unknown:
                raise InputError(f"effects: unknown effect(s) {', '.join(unknown)} "
                                 f"(vocabulary: {', '.join(words)})", parameter="effects", value=self.effects)
        return frames

    # -- the pipeline ------------------------------------------------------------------
    def fit(self, measurements, y=None, *, progress=None, references=()) -> "GapDiagnosis":
        """Run the diagnosis on measurements of ``self.robot``.

        Parameters
        ----------
        measurements : MeasurementSet, or list of (RobotModel, MeasurementSet)
            The measured rows (see :func:`diagnose`).
        y : None
            Not used: the measured positions are in ``measurements`` (scikit-learn's
            ``fit(X, y)`` slot, kept so that the estimator fits in its tools).
        progress : callable(str), default=None
            Called with a short message as the work advances.
        references : list of (frame, position, measured, time_s), default=()
            Base references (see :func:`diagnose`).

        Returns
        -------
        GapDiagnosis
            self, fitted.
        """
        validate_hyperparameters(self)
        if isinstance(measurements, RobotModel):  # the 0.1 form fit(robot, measurements)
            warnings.warn("GapDiagnosis.fit(robot, measurements) is deprecated and will be removed in 0.2; "
                          "use GapDiagnosis(robot=robot, ...).fit(measurements)", DeprecationWarning, stacklevel=2)
            robot, measurements = measurements, y
        else:
            robot = self.robot
        if robot is None and not isinstance(measurements, (list, tuple)):
            raise InputError("GapDiagnosis.fit: no robot; give it as GapDiagnosis(robot=...)")
        with _one_blas_thread():
            return self._fit(robot, measurements, progress, list(references))

    def _fit(self, robot, measurements, progress, references) -> "GapDiagnosis":
        """The stages of :mod:`tcr_accuracy.diagnosis.stages`, in order."""
        frames = self._check(robot, measurements)
        tcp_given = self._tcp_offset()
        say = progress or (lambda message: None)
        seed = int_seed(self.random_state)
        rng = np.random.default_rng(seed)  # one stream, drawn in stage order: folds, structure test, residual
        names = [e for e in vocabulary() if self.effects is None or e in self.effects or e == "frames"]
        say("registering the tracker frame")
        registered = register_measurements(frames, references, self.orientation_weight, self.instrument)
        say("building effect models")
        repeats = self.fold_repeats if self.fold_repeats is not None else \
            int(np.clip(round(10_000 / registered.n_rows), 1, 5))
        candidates, selection, setup = self._select(registered, names, repeats, rng, seed, say)
        attribution = attribute_effects(registered, candidates, selection, selection_z=self.selection_z,
                                        min_relative_gain=self.min_relative_gain,
                                        stability_replays=self.stability_replays, seed=seed, say=say)
        candidates.engine.release_fold_blocks()  # every model is fitted: the residual tests' memory
        residual = analyse_residual(registered, candidates, selection, tracker_noise=self.tracker_noise, rng=rng,
                                    seed=seed, say=say)
        parameters = collect_parameters(registered, candidates, selection, tcp_given)
        first_order = first_order_reach(registered.parts[0], candidates.bases,
                                        [e for e in selection.selected if e != "frames"], parameters.full_vectors,
                                        registered.nominal[0].position, residual.noise_floor)
        stages = DiagnosisStages(register=registered, candidates=candidates, select=selection,
                                 attribute=attribution, residual=residual, parameters=parameters,
                                 first_order=first_order, setup=setup)
        self.result_ = Diagnosis(robot_name=registered.robot.name, n_measurements=registered.n_rows,
                                 folds=self.folds, stages=stages, n_fits=candidates.engine.n_fits,
                                 joint_names=list(registered.robot.joint_names), source=_source_of(measurements))
        self.robot_ = registered.robot
        self.engine_ = candidates.engine
        self.selected_effects_ = list(selection.selected)
        self.primary_effect_ = attribution.primary_effect
        self.parameters_ = parameters.values
        self.noise_ = residual.noise
        return self

    def _select(self, registered, names, repeats: int, rng, seed: int, say) -> tuple:
        """Stages 2 and 3 (the candidates, the selection) and, with several sessions, what each owns
        (:mod:`.stages.setup`): chosen with frames alone for the selection, judged again with the
        selection's effects, and the selection run once more where that judgement differs."""
        setup = None
        if len(registered.session_labels) > 1:
            say("choosing what each session owns")
            from sklearn.model_selection import RepeatedKFold

            kfold = RepeatedKFold(n_splits=self.folds, n_repeats=repeats, random_state=int(seed) + 5)
            every = [(np.asarray(a), np.asarray(b)) for a, b in kfold.split(np.arange(registered.n_rows))]
            setup = compare_setups(registered, [every[r * self.folds:(r + 1) * self.folds] for r in range(repeats)],
                                   rank_tol=self.rank_tol, min_motion=0.0)
        for attempt in range(2):
            candidates = build_candidates(registered, names, folds=self.folds, rank_tol=self.rank_tol,
                                          tracker_noise=self.tracker_noise, rng=rng, fold_repeats=repeats,
                                          instrument=self.instrument,
                                          frames_options=setup.options if setup is not None else None)
            say("fitting frames")
            selection = select_effects(registered, candidates, selection_z=self.selection_z,
                                       min_relative_gain=self.min_relative_gain, say=say)
            if setup is None:
                return candidates, selection, None
            engine = candidates.engine
            # judged with the chosen effects; the second time, the setup the selection ran with is kept
            judged = compare_setups(registered, engine.repeats, rank_tol=engine.rank_tol, min_motion=engine.min_motion,
                                    effects=selection.selected, bases=engine.bases, jacobians=candidates.linearised(),
                                    keep=setup.chosen if attempt else None)
            if judged.chosen == setup.chosen:
                return candidates, selection, dataclasses.replace(judged, reselected=attempt == 1)
            setup = judged
        raise AssertionError("unreachable: the second judgement keeps the setup")

    def _tcp_offset(self) -> np.ndarray | None:
        """The given TCP offset (3,) [m], checked: three finite numbers within 10 m."""
        if self.tcp_offset is None:
            return None
        try:
            offset = np.asarray(self.tcp_offset, dtype=float)
        except (TypeError, ValueError):
            offset = np.full(0, np.nan)
        if offset.shape != (3,) or not np.all(np.isfinite(offset)) or np.linalg.norm(offset) > 10.0:
            raise InputError(f"tcp_offset={self.tcp_offset!r}: want three finite numbers [m], within 10 m of the tool "
                             "frame", parameter="tcp_offset", value=self.tcp_offset)
        return offset

    def ladder(self, effects) -> list[Step]:
        """The shrink table along a given order of effects (``frames`` first), on the same data,
        folds and identifiability as the fit: e.g. to set the diagnosis next to a published
        calibration ladder. Effects that could not be fitted on these data raise InputError."""
        if not hasattr(self, "engine_"):
            raise AnalysisError("GapDiagnosis.ladder: call fit first")
        engine = self.engine_
        sequence = ["frames"] + [e for e in effects if e != "frames"]
        missing = [e for e in sequence if e not in engine.bases]
        if missing:
            raise InputError(f"ladder: {', '.join(missing)} cannot be fitted on these data")
        steps, previous = [], None
        for k, effect in enumerate(sequence):
            with _one_blas_thread():
                r = engine.evaluate(ordered(sequence[:k + 1]), exact=True)
            z = None if previous is None else paired_z(previous["heldout_residual"], r["heldout_residual"])
            steps.append(Step(effect, tuple(ordered(sequence[:k + 1])), r["n_parameters"],
                              r["train_stats"].rms, ErrorStats.of(r["heldout_residual"]), z))
            previous = r
        return steps

    def fitted_model(self, effects) -> tuple[list, list]:
        """The effects of a set (``frames`` added) as fitted to all the data, for the first
        measured frame: (effect instances, their full parameter vectors [SI]) -- e.g. the
        rival models of an ambiguity group, to predict them where they differ."""
        if not hasattr(self, "engine_"):
            raise AnalysisError("GapDiagnosis.fitted_model: call fit first")
        engine = self.engine_
        names = ordered(set(effects) | {"frames"})
        missing = [e for e in names if e not in engine.bases]
        if missing:
            raise InputError(f"fitted_model: {', '.join(missing)} cannot be fitted on these data")
        with _one_blas_thread():
            result = engine.evaluate(names, exact=True)
        theta = result["phi"] * result["scale"]
        instances, vectors, offset = [], [], 0
        for e in names:
            b, keep = engine.bases[e], result["keep"][e]
            union = np.zeros(len(b.names))
            union[keep] = theta[offset:offset + keep.size]
            offset += keep.size
            instances.append(b.per_part[0].effect)
            vectors.append(union[b.index[0]])
        return instances, vectors

    def predict(self, q: np.ndarray, context: MeasurementContext | None = None) -> np.ndarray:
        """(N, 3) TCP position errors [m] in the robot's base frame that the fitted model predicts
        at joints q (N, n_joints): its TCP minus the nominal robot's, as every estimator's
        ``predict`` (:func:`tcr_accuracy.make_predictor`); :meth:`tracker_positions` gives what
        the tracker would measure.

        Parameters
        ----------
        q : array-like of shape (N, n_joints)
            Commanded joint values [rad, m].
        context : MeasurementContext, optional
            The rows' payload, temperature, ... (None: the defaults).

        Returns
        -------
        ndarray of shape (N, 3)
        """
        if not hasattr(self, "result_"):
            raise AnalysisError("GapDiagnosis.predict: call fit first")
        return self.result_.predict(self.robot_, q, context)

    def tracker_positions(self, q: np.ndarray, context: MeasurementContext | None = None) -> np.ndarray:
        """(N, 3) TCP positions [m] in the tracker frame the fitted model predicts at joints q
        (N, n_joints) (:meth:`Diagnosis.tracker_positions`).

        Parameters
        ----------
        q : array-like of shape (N, n_joints)
        context : MeasurementContext, optional

        Returns
        -------
        ndarray of shape (N, 3)
        """
        if not hasattr(self, "result_"):
            raise AnalysisError("GapDiagnosis.tracker_positions: call fit first")
        return self.result_.tracker_positions(self.robot_, q, context)


def _measurement_set(measurements) -> MeasurementSet:
    if not isinstance(measurements, MeasurementSet):
        raise InputError(f"the diagnosis reads a MeasurementSet, not {type(measurements).__name__}")
    return measurements


def _source_of(measurements) -> str:
    """Where the measurements came from (a MeasurementSet's ``source``; the first frame's of a list)."""
    if isinstance(measurements, (list, tuple)):
        measurements = measurements[0][1]
    return str(getattr(measurements, "source", "the measurements"))
