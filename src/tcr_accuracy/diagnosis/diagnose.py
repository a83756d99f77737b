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
import math
import warnings

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation
from sklearn.base import BaseEstimator

from ..model.context import CONTEXT_FIELDS, MeasurementContext
from .result import Diagnosis, ErrorStats, Observations, Step, observations_from
from ..effects import effect_class, make_effect, vocabulary
from ..model.errors import ErrorModel
from ..exceptions import AnalysisError, InputError
from .fitting import EffectBasis, FitEngine, Part, UnionBasis, ordered, paired_z, position_jacobians, register, stacked
from ..model.gravity import gravity_torque
from ..model.kinematics import tcp_poses
from .ambiguity import ambiguity_report, settle_swaps, stand_in_shapes, swap_alternatives
from .residuals import NoiseEstimate, noise_from_repeats, noise_from_residual, noise_from_rigid_frames, \
    tracker_drift, where_analysis
from .uncertainty import difference_interval, joint_function_bands, outside_physics, parameter_table, \
    selection_frequency
from .attribution import contributions, fixed_point_check, tied_own_shares
from .structure import StructureDetector, name_scatter, scatter_beyond_noise, smallest_detectable_structure, \
    smooth_shape, structure_verdict
from ..model.robot import RobotModel
from ..random_state import int_seed, renamed_keyword

#: Noise figure [m per axis] the identifiability test resolves down to a tenth of when the
#: instrument's is not known (a good laser tracker): pruning stays rank-based.
RESOLUTION_NOISE = 2e-5


# ---------------------------------------------------------------------------------------
# The diagnosis
# ---------------------------------------------------------------------------------------
@renamed_keyword("seed", "random_state")
def diagnose(robot: RobotModel, measurements, *, effects=None, folds: int = 5, random_state=0,
             tracker_noise: float | None = None, selection_z: float = 3.0, min_relative_gain: float = 0.002,
             rank_tol: float = 1e-6, orientation_weight: float | None = None, progress=None,
             references=()) -> Diagnosis:
    """Diagnose the gap between the nominal robot and its measurements.

    The function form of :class:`GapDiagnosis`: ``GapDiagnosis(robot=robot, ...).fit(measurements).result_``.

    Parameters
    ----------
    robot : RobotModel
        The nominal model (of the measured frame).
    measurements : MeasurementSet, Observations, or list of (RobotModel, MeasurementSet)
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
    references : list of (frame, position (3,) [m], measured (N, 3) [m], time_s (N,) or None), default=()
        Base references: frames fixed to the robot's base (their place in the base frame), measured on
        the same rows in the tracker frame: they pin the tracker frame and show its drift
        (estimated per session, corrected where significant and larger than the noise).

    Returns
    -------
    Diagnosis
        Everything found, SI units; ``print(result.summary())`` prints what the command line does.

    Examples
    --------
    >>> import numpy as np, tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> scenario = tcr.load_scenario("examples/scenario_compliance.yaml")  # doctest: +SKIP
    >>> measured, truth = tcr.simulate_measurements(robot, scenario, 200, random_state=1)  # doctest: +SKIP
    >>> tcr.diagnose(robot, measured).primary_effect  # doctest: +SKIP
    'compliance'
    """
    return GapDiagnosis(robot=robot, effects=effects, folds=folds, random_state=random_state,
                        tracker_noise=tracker_noise, selection_z=selection_z, min_relative_gain=min_relative_gain,
                        rank_tol=rank_tol, orientation_weight=orientation_weight).fit(
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
        Bootstrap replays of the selection that give each effect's selection frequency.

    Attributes
    ----------
    result_ : Diagnosis
        Everything found (SI units); ``result_.summary()`` is the printed summary.
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
    >>> estimator = tcr.GapDiagnosis(robot=robot, folds=5, random_state=0)
    >>> estimator.get_params()["folds"]
    5
    >>> estimator.fit(measured).selected_effects_  # doctest: +SKIP
    ['frames', 'compliance', 'geometry', 'joint_offsets']
    """

    @renamed_keyword("seed", "random_state")
    def __init__(self, *, robot=None, effects=None, folds: int = 5, random_state=0,
                 tracker_noise: float | None = None, selection_z: float = 3.0, min_relative_gain: float = 0.002,
                 rank_tol: float = 1e-6, orientation_weight: float | None = None, stability_replays: int = 50):
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
    def _check(self, robot, measurements) -> list[tuple[RobotModel, Observations, str]]:
        if isinstance(measurements, (list, tuple)):
            frames = [(r, observations_from(m), r.tool_frame) for r, m in measurements]
        else:
            frames = [(robot, observations_from(measurements), robot.tool_frame)]
        if self.folds < 2:
            raise InputError(f"--folds {self.folds}: need at least 2")
        n = len(frames[0][1])
        for r, obs, label in frames:
            if obs.q.ndim != 2 or obs.q.shape[1] != r.n_joints:
                raise InputError(f"measurements have {obs.q.shape[-1]} joint columns, {r.name} has {r.n_joints}")
            if len(obs) != n:
                raise InputError(f"measured frame {label}: {len(obs)} rows, the first frame has {n}")
        if n < max(3 * self.folds, 12):
            raise InputError(f"{n} measurements are too few to diagnose with {self.folds}-fold cross-validation "
                             f"(need at least {max(3 * self.folds, 12)})")
        words = vocabulary()
        if self.effects is not None:
            unknown = [e for e in self.effects if e not in words]
            if unknown:
                raise InputError(f"--effects: unknown effect(s) {', '.join(unknown)} "
                                 f"(vocabulary: {', '.join(words)})")
        return frames

    # -- the pipeline ------------------------------------------------------------------
    def fit(self, measurements, y=None, *, progress=None, references=()) -> "GapDiagnosis":
        """Run the diagnosis on measurements of ``self.robot``.

        Parameters
        ----------
        measurements : MeasurementSet, Observations, or list of (RobotModel, MeasurementSet)
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
        from sklearn.model_selection import KFold

        frames = self._check(robot, measurements)
        robot, obs = frames[0][0], frames[0][1]
        n = len(obs)
        say = progress or (lambda message: None)
        seed = int_seed(self.random_state)
        rng = np.random.default_rng(seed)
        names = [e for e in vocabulary() if self.effects is None or e in self.effects or e == "frames"]
        notes: list = []
        measured = set().union(*(set(o.measured) for _, o, _ in frames))

        # 1. register the tracker frame (each session's own), then work in the robot's base frame
        say("registering the tracker frame")
        nominal = [tcp_poses(r, o.q) for r, o, _ in frames]
        sessions = list(obs.session_labels) if len(obs.session_labels) > 1 else []
        session_of = obs.context.session if sessions else np.zeros(n, dtype=int)
        # base references: the tracker's drift per session, taken out of every measured position
        drift, drift_report, reference_noise = tracker_drift(references, session_of, max(len(sessions), 1), sessions)
        if references:
            frames = [(r, dataclasses.replace(o, position=o.position - drift), label) for r, o, label in frames]
            references = [(f, nominal_ref, measured - drift, t) for f, nominal_ref, measured, t in references]
            obs = frames[0][1]
        stations = []
        for s in range(max(len(sessions), 1)):
            rows_s = np.flatnonzero(session_of == s)
            if sessions and rows_s.size < 3:
                raise InputError(f"session {sessions[s]}: {rows_s.size} measurements, a session's tracker frame "
                                 "needs at least 3")
            # the references' fixed places pin the frame with the moving points
            fixed = [np.asarray(nominal_ref, dtype=float)[None] for _, nominal_ref, _, _ in references]
            seen = [measured[rows_s].mean(axis=0)[None] for _, _, measured, _ in references]
            stations.append(register(np.concatenate([p.position[rows_s] for p in nominal] + fixed),
                                     np.concatenate([o.position[rows_s] for _, o, _ in frames] + seen)))
        rot, trans = stations[0]
        weight = self.orientation_weight
        if weight is None:
            points = np.concatenate([o.position for _, o, _ in frames])
            weight = float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))
        parts = []
        for (r, o, label) in frames:
            target_rotation = None
            if o.quaternion is not None:
                w, x, y, z = o.quaternion.T
                tracker_rotation = Rotation.from_quat(np.stack([x, y, z, w], axis=1)).as_matrix()
                station_rotation = np.stack([stations[s][0] for s in session_of])
                target_rotation = np.einsum("nji,njk->nik", station_rotation, tracker_rotation)  # R^T R_tracker
            in_base = np.empty_like(o.position)
            for s, (rot_s, trans_s) in enumerate(stations):
                rows_s = session_of == s
                in_base[rows_s] = (o.position[rows_s] - trans_s) @ rot_s
            parts.append(Part(r, o.q, in_base, o.context, label, target_rotation, weight))
        if any(p.target_rotation is not None for p in parts):
            notes.append(f"measured orientation enters the fit: rotation errors [rad] weighted by {weight:.4g} m/rad "
                         "(an angle counts as the position error it makes at the measured points' RMS spread "
                         "about their centre)")
        tau = gravity_torque(robot, obs.q, obs.context.payload_kg, outside_q=obs.context.outside_q)

        # effects as linear maps, and which can be tried at all
        say("building effect models")
        # an effect of last resort is built only if it is tried (its maps are the largest: tens of MB per 10^4 poses)
        late_names = [e for e in names if effect_class(e).last_resort]
        bases, candidates, stochastic = self._bases(parts, [e for e in names if e not in late_names], measured,
                                                    notes, sessions)
        if "frames" not in bases:
            raise AnalysisError("the frames effect could not be built")
        order = ordered(bases)
        # a TCP offset of centimetres changes which directions duplicate one another:
        # linearise about the frames-only fit, not the nominal model
        pre = FitEngine(parts, {"frames": bases["frames"]}, [], rank_tol=0.0)
        frames_cols = pre.columns(["frames"])
        phi, _ = pre.fit(frames_cols, np.arange(n))
        linearised = []  # per part, the error Jacobians at the frames-only fit
        for p, part in enumerate(parts):
            basis, _, idx = frames_cols.per_part[p]
            # the sessions' base twists differ a little after their own registrations: their mean
            x_frames = basis.errors(phi[idx] * frames_cols.scale[idx]).mean(axis=0)
            linearised.append(position_jacobians(part.robot, part.q, x_frames,
                                                 weight if part.target_rotation is not None else None))
        _relinearise(bases, linearised)
        kfold = KFold(n_splits=self.folds, shuffle=True, random_state=int(rng.integers(2**31 - 1)))
        split = [(np.asarray(a), np.asarray(b)) for a, b in kfold.split(np.arange(n))]
        # the instrument's noise from the data's own redundancy: reflectors on one rigid body, else repeated poses
        repeats = None
        if self.tracker_noise is None:
            repeats = noise_from_rigid_frames([p.position for p in nominal], [o.position for _, o, _ in frames],
                                              [label for _, _, label in frames]) or reference_noise or \
                noise_from_repeats(obs.q, obs.position, _context_table(obs))
        resolution = self.tracker_noise or (repeats.per_axis if repeats else RESOLUTION_NOISE)
        engine = FitEngine(parts, bases, split, self.rank_tol, min_motion=0.1 * resolution)
        _, ident_all = engine.identify(order)
        testable = []
        for name in order:
            if name != "frames" and engine.identify(("frames", name))[0][name].size == 0:
                candidates[name] = {"tried": False, "why": "no identifiable parameter on these data (beyond frames)"}
            elif name != "frames":
                testable.append(name)

        # 2. gap after frames; 3. forward selection, backward elimination
        say("fitting frames")
        result = engine.evaluate(["frames"])
        gap_residual = result["train_residual"]
        steps = [Step("frames", ("frames",), result["n_parameters"], ErrorStats.of(result["train_residual"]).rms,
                      ErrorStats.of(result["heldout_residual"]), None)]
        current = self._forward(engine, testable, steps, candidates, say)
        # a flexible effect of last resort is tried only where the others leave structure in joint space
        say("testing what the first selection leaves")
        detector = StructureDetector(obs.q, rng, kinds=robot.joint_kinds)
        late = []
        if late_names and detector.test(_first_frame(engine.evaluate(ordered(current))["train_residual"]),
                                        rng)["remains"]:
            late_bases, late_candidates, _ = self._bases(parts, late_names, measured, notes, sessions)
            _relinearise(late_bases, linearised)
            engine.add_bases(late_bases)
            candidates.update(late_candidates)
            for name in ordered(late_bases):
                if engine.identify(("frames", name))[0][name].size == 0:
                    candidates[name] = {"tried": False, "why": "no identifiable parameter on these data (beyond frames)"}
                else:
                    late.append(name)
            testable += late
            current = self._forward(engine, testable, steps, candidates, say, current)
        else:
            for e in late_names:
                candidates[e] = {"tried": False, "why": "tried only when the other effects leave structure in joint "
                                                        "space, and they left none"}
        self._judge_at_fitted_sizes(engine, current, notes)
        # a stand-in must explain the gap on its own, as an effect entering first would have to
        # (its paired z against frames alone at the first step): the rest cannot replace anything
        rivals = [e for e in testable if candidates.get(e, {}).get("z", 0.0) > self.selection_z]
        current, swaps = settle_swaps(engine, current, rivals, self.selection_z, say)
        current, loo, eliminated = self._backward(engine, current, say)
        selected = list(current)  # forward order, swaps in place, without what backward elimination dropped
        chosen = [e for e in selected if e != "frames"]
        final = engine.evaluate(ordered(current))
        groups = swap_alternatives(engine, current, rivals, self.selection_z)
        ambiguous = ambiguity_report(groups)
        # the largest own share and those it does not clear, compared on the same held-out rows (paired: the
        # two shares' own intervals overlap more than their difference's does)
        tied = tied_own_shares(engine, current, loo, self.selection_z)
        primary = tied[0] if tied else None
        primary_group = [r["effect"] for r in groups.get(primary, [])] or ([primary] if primary else [])
        primary_group += [e for e in tied[1:] if e not in primary_group]
        if len(primary_group) > 1:
            primary = None  # the data cannot say which of the group it is
            primary_group = ordered(primary_group)
        # the shrink table in the order the chosen effects explain the data
        steps = self._explanation_ladder(engine, selected, steps[0])
        say("selection stability")
        selection = selection_frequency(engine, testable, self.selection_z, self.min_relative_gain,
                                        self.stability_replays, np.random.default_rng([seed, 2]), say,
                                        late=[e for e in late if e in testable])
        say("what the data fit only outside physics")
        beyond = outside_physics(engine, current, [e for e in testable], self.selection_z, self.min_relative_gain)
        # an effect in the model that the data fit significantly better beyond its physics is not named as the cause
        flagged = [f["effect"] for f in beyond if f["effect"] in current]
        if flagged and (set(flagged) & set(primary_group)):
            primary_group = [e for e in primary_group if e not in flagged]
            if not primary_group:
                shares = {r["dropped"]: r["own_share_increase_mm"] for r in loo if r["dropped"] not in flagged}
                primary_group = [max(shares, key=shares.get)] if shares else []
            primary = primary_group[0] if len(primary_group) == 1 else None
            tied = [e for e in tied if e not in flagged]
            notes.append(f"{', '.join(flagged)} stays in the model only at its physical bound and is not named as the "
                         "cause: see what the data fit outside physics")
        if eliminated:
            notes.append("dropped again after forward selection (no significant held-out loss without them): "
                         + ", ".join(f"{e['effect']} (z = {e['z']:.1f})" for e in eliminated))
        for swap in swaps:
            notes.append(f"{swap['in']} replaces {swap['out']} (one-standard-error rule: held-out RMS "
                         f"{swap['heldout_rms_mm'][swap['in']]:.4g} mm with {swap['n_parameters'][swap['in']]} "
                         f"parameters against {swap['heldout_rms_mm'][swap['out']]:.4g} mm with "
                         f"{swap['n_parameters'][swap['out']]})")

        # where (on the frames-only residual), structure, noise and scatter (on the final residual)
        say("where the gap lies")
        first = _first_frame
        context = {k: np.asarray(getattr(obs.context, k), dtype=float) for k in obs.measured}
        where, semis = where_analysis(robot, obs.q, nominal[0].position, first(gap_residual), tau, context, rng=rng)
        say("testing the final residual")
        final_train = first(final["train_residual"])
        structure = detector.test(final_train, rng)
        noise = self._noise(repeats, obs.q, final_train, final["n_parameters"], structure["remains"])
        scatter = scatter_beyond_noise(noise, final, stochastic)
        say("probing the structure test's power")
        probe_rng = np.random.default_rng([seed, 1])
        shapes = stand_in_shapes(engine, current, testable, probe_rng) or \
            {"smooth joint function": smooth_shape(detector, probe_rng)}
        structure["power"] = smallest_detectable_structure(detector, shapes, noise.per_axis, probe_rng)
        leftover = math.sqrt(3.0) * (scatter["estimated_noise_per_axis_mm"] * 1e-3 if scatter["tested"]
                                     else float(np.sqrt(np.mean(final_train**2))))
        structure.update(structure_verdict(structure, structure["power"], scatter, math.sqrt(3.0) * noise.per_axis,
                                           leftover))
        name_scatter(scatter, structure, stochastic, noise, notes, detector, final_train)

        # fitted parameters, as-built geometry, tracker frame
        keep, ident = engine.identify(tuple(ordered(selected)))
        ident = {**ident, "all_effects": ident_all}
        table = parameter_table(final, bases, ordered(selected))
        for e, rows in table.items():
            for pinned in rows["pinned"]:
                if not (pinned["bound"] == "lower" and rows["range"][pinned["parameter"]][0] == 0.0):
                    notes.append(f"{pinned['parameter']} is held at its physical {pinned['bound']} bound "
                                 f"({effect_class(e).physics}): the data push beyond it")
        for finding in beyond:
            notes.append(f"outside physics: {finding['description']} (with {finding['effect']} unbounded the "
                         f"held-out RMS would be {finding['heldout_rms_mm']:.4g} mm instead of "
                         f"{finding['heldout_rms_bounded_mm']:.4g} mm, z = {finding['z']:.1f}; not named as a cause)")
        theta = final["phi"] * final["scale"]
        parameters, units, full_parameters = {}, {}, {}
        em = ErrorModel(robot)
        as_built = np.zeros(em.size)
        offset = 0
        for e in ordered(selected):
            b = bases[e]
            union = np.zeros(len(b.names))
            union[keep[e]] = theta[offset:offset + keep[e].size]
            offset += keep[e].size
            parameters[e] = {b.names[k]: union[k] for k in keep[e]}
            units[e] = {b.names[k]: b.units[k] for k in keep[e]}
            full = union[b.index[0]]  # the first frame's own parameter vector
            full_parameters[e] = full
            if effect_class(e).geometric:
                as_built += b.per_part[0].basis.errors(full, rows=[0])[0]
        contribution = contributions(parts[0], bases, chosen, full_parameters, nominal[0].position)
        second_order = fixed_point_check(parts[0], bases, full_parameters, math.sqrt(3.0) * noise.per_axis, notes)
        base_twist = as_built[em.base_slice].copy()
        as_built[em.base_slice] = 0.0  # the base twist belongs to the tracker frame, not the robot
        tracker = np.eye(4)
        tracker[:3, :3], tracker[:3, 3] = rot, trans
        tracker = tracker @ pin.exp6(base_twist).homogeneous

        held = final["heldout_residual"]
        by_session = []
        for s, label in enumerate(sessions):
            rows_s = np.flatnonzero(session_of == s)
            station = np.eye(4)
            station[:3, :3], station[:3, 3] = stations[s]
            temperature = np.asarray(obs.context.temperature_c, dtype=float)[rows_s]
            by_session.append({"session": label, "n_measurements": int(rows_s.size),
                               "gap": ErrorStats.of(first(gap_residual)[rows_s]).to_dict(),
                               "heldout": ErrorStats.of(first(held)[rows_s]).to_dict(),
                               "temperature_c": [float(temperature.min()), float(temperature.max())],
                               "registration_base_to_tracker": station.tolist()})
        by_frame = {}
        if len(parts) > 1:
            by_frame = {part.label: ErrorStats.of(held[p]) for p, part in enumerate(parts)}
        orientation = {}
        if final["heldout_orientation"] is not None:
            angle = np.degrees(np.linalg.norm(stacked(final["heldout_orientation"]), axis=1))
            orientation = {"weight_m_per_rad": weight, "heldout_mean_deg": float(angle.mean()),
                           "heldout_rms_deg": float(np.sqrt(np.mean(angle**2))), "heldout_max_deg": float(angle.max())}
        self.result_ = Diagnosis(
            robot_name=robot.name, n_measurements=n, folds=self.folds, gap=ErrorStats.of(gap_residual), where_mm=where,
            identifiability=ident, candidates=candidates, steps=steps, selected_effects=selected,
            primary_effect=primary, leave_one_out=loo, noise_floor=math.sqrt(3.0) * noise.per_axis,
            tracker_noise=noise.per_axis, scatter=scatter, structure=structure, parameters=parameters,
            parameter_units=units, as_built_x=as_built, tracker_transform=tracker, final_residual=final_train,
            heldout_residual=first(held), gap_residual=first(gap_residual), q=obs.q,
            nominal_position=nominal[0].position, gravity_torque=tau, notes=notes, semivariograms=semis,
            effect_parameters=full_parameters, registration=(rot, trans), eliminated=eliminated,
            n_fits=engine.n_fits, contribution=contribution, noise=noise, ambiguous=ambiguous, swaps=swaps,
            primary_group=primary_group, primary_tied=tied, second_order=second_order,
            frames_measured=[p.label for p in parts], heldout_by_frame=by_frame, orientation=orientation,
            parameter_table=table, selection=selection, outside_physics=beyond,
            physics={e: effect_class(e).physics for e in table},
            effect_options={e: dict(bases[e].per_part[0].effect.options) for e in ordered(selected)},
            sessions=by_session, drift=drift_report,
            joint_function_bands=joint_function_bands(final, bases, ordered(selected), obs.q),
            joint_names=list(robot.joint_names), source=_source_of(measurements),
        )
        self.robot_ = robot
        self.engine_ = engine
        self.selected_effects_ = selected
        self.primary_effect_ = primary
        self.parameters_ = parameters
        self.noise_ = noise
        return self

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
                r = engine.evaluate(ordered(sequence[:k + 1]))
            z = None if previous is None else paired_z(previous["heldout_residual"], r["heldout_residual"])
            steps.append(Step(effect, tuple(ordered(sequence[:k + 1])), r["n_parameters"],
                              ErrorStats.of(r["train_residual"]).rms, ErrorStats.of(r["heldout_residual"]), z))
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
            result = engine.evaluate(names)
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
        """(N, 3) TCP positions [m] in the tracker frame that the fitted model predicts at q (N, n)."""
        if not hasattr(self, "result_"):
            raise AnalysisError("GapDiagnosis.predict: call fit first")
        return self.result_.predict(self.robot_, q, context)

    # -- pieces ------------------------------------------------------------------------
    def _bases(self, parts, names, measured, notes, part_sessions=()):
        bases, candidates, stochastic = {}, {}, []
        jacobians = {}  # per part, the error Jacobians at the nominal model: the same for every effect
        for name in names:
            cls = effect_class(name)
            if cls.stochastic:
                stochastic.append(name)
                candidates[name] = {"tried": False, "why": "stochastic: tested as extra scatter, not fitted"}
                continue
            missing = [c for c in cls.context_columns if c in CONTEXT_FIELDS and CONTEXT_FIELDS[c] not in measured]
            if missing and cls.requires_context:
                candidates[name] = {"tried": False, "why": f"needs the {', '.join(missing)} column"}
                continue
            try:
                per_part = []
                for p, part in enumerate(parts):
                    options = {"tool_rotation": True} if name == "frames" and part.target_rotation is not None else {}
                    if name == "frames" and len(part_sessions) > 1:
                        options["sessions"] = tuple(part_sessions)
                    options.update(cls.options_for_data(part.robot, part.q, part.context))
                    effect = make_effect(name, part.robot, **options)
                    labels = _part_names(effect, part, len(parts))
                    em = ErrorModel(part.robot)
                    if p not in jacobians:
                        jacobians[p] = position_jacobians(
                            part.robot, part.q, None,
                            part.orientation_weight if part.target_rotation is not None else None)
                    per_part.append(EffectBasis(effect, part, em, jacobians[p], labels))
                basis = UnionBasis(per_part)
            except InputError as exc:
                candidates[name] = {"tried": False, "why": f"not testable on these data: {exc}"}
                continue
            if basis.nonlinearity > 1e-6:
                notes.append(f"{name} is nonlinear in its parameters (relative {basis.nonlinearity:.1e}); "
                             "it is fitted in its linearisation about zero")
            bases[name] = basis
        return bases, candidates, stochastic

    def _forward(self, engine, testable, steps, candidates, say, start=None) -> list:
        """Forward selection from ``start`` (default frames alone) over the testable effects;
        each effect's first trial is recorded in ``candidates`` (against frames alone, or
        against the model it was first tried on)."""
        current = ["frames"] if start is None else list(start)
        pool = [e for e in testable if e not in current]
        fresh = [e for e in pool if "z" not in candidates.get(e, {})]
        while pool:
            trials = {}
            for e in pool:
                say(f"step {len(steps)}: trying {e}")
                trials[e] = engine.evaluate(ordered(current + [e]))
            prev = engine.evaluate(ordered(current))
            prev_rms = ErrorStats.of(prev["heldout_residual"]).rms
            for e in fresh:
                r = trials[e]
                rms = ErrorStats.of(r["heldout_residual"]).rms
                candidates[e] = {"tried": True, "heldout_rms_mm_with_frames": rms * 1e3,
                                 "gain_mm": (prev_rms - rms) * 1e3,
                                 "z": paired_z(prev["heldout_residual"], r["heldout_residual"]),
                                 "n_parameters": r["n_parameters"] - prev["n_parameters"]}
                if len(current) > 1:
                    candidates[e]["added_to"] = list(current)
            fresh = []
            best = min(trials, key=lambda e: ErrorStats.of(trials[e]["heldout_residual"]).rms)
            r = trials[best]
            rms = ErrorStats.of(r["heldout_residual"]).rms
            z = paired_z(prev["heldout_residual"], r["heldout_residual"])
            if not (z > self.selection_z and rms < prev_rms * (1.0 - self.min_relative_gain)):
                break
            current.append(best)
            pool.remove(best)
            steps.append(Step(best, tuple(ordered(current)), r["n_parameters"],
                              ErrorStats.of(r["train_residual"]).rms, ErrorStats.of(r["heldout_residual"]), z))
        return current

    def _backward(self, engine, current, say):
        """Backward elimination: an effect that no longer earns its place once the others are
        in (a flexible one picked early that later effects explain better) goes out."""
        eliminated = []
        while True:
            chosen = [e for e in current if e != "frames"]
            final = engine.evaluate(ordered(current))
            final_rms = ErrorStats.of(final["heldout_residual"]).rms
            keep = engine.identify(tuple(ordered(current)))[0]
            loo = []
            for e in chosen:
                say(f"leave-one-out: {e}")
                rest = ordered([s for s in current if s != e])
                r = engine.evaluate(rest)
                own = engine.evaluate(rest, keep={s: keep[s] for s in rest})
                held, held_own = ErrorStats.of(r["heldout_residual"]), ErrorStats.of(own["heldout_residual"])
                share = difference_interval(own["heldout_residual"], final["heldout_residual"])
                loo.append({"dropped": e, "heldout_rms_mm": held.rms * 1e3, "heldout_mean_mm": held.mean * 1e3,
                            "own_share_interval_mm": [share[1] * 1e3, share[2] * 1e3],
                            "heldout_max_mm": held.max * 1e3, "increase_mm": (held.rms - final_rms) * 1e3,
                            "z": paired_z(r["heldout_residual"], final["heldout_residual"]),
                            "own_share_heldout_rms_mm": held_own.rms * 1e3,
                            "own_share_heldout_mean_mm": held_own.mean * 1e3,
                            "own_share_increase_mm": (held_own.rms - final_rms) * 1e3})
            weakest = min(loo, key=lambda row: row["z"]) if loo else None
            if weakest is None or weakest["z"] > self.selection_z:
                return current, loo, eliminated
            eliminated.append({"effect": weakest["dropped"], "z": weakest["z"],
                               "increase_mm": weakest["increase_mm"]})
            current.remove(weakest["dropped"])

    def _explanation_ladder(self, engine, selected, first: Step) -> list[Step]:
        """The shrink table in the order of explanation: from frames, each step adds the chosen
        effect that lowers the held-out error most given those before it, with its gain and
        the gain's 95 % interval."""
        steps, current = [first], ["frames"]
        previous = engine.evaluate(["frames"])
        remaining = [e for e in selected if e != "frames"]
        while remaining:
            trials = {e: engine.evaluate(ordered(current + [e])) for e in remaining}
            best = min(trials, key=lambda e: ErrorStats.of(trials[e]["heldout_residual"]).rms)
            r = trials[best]
            current.append(best)
            remaining.remove(best)
            steps.append(Step(best, tuple(ordered(current)), r["n_parameters"], ErrorStats.of(r["train_residual"]).rms,
                              ErrorStats.of(r["heldout_residual"]),
                              paired_z(previous["heldout_residual"], r["heldout_residual"]),
                              difference_interval(previous["heldout_residual"], r["heldout_residual"])))
            previous = r
        return steps

    def _noise(self, repeats, q, residual, n_parameters, structured) -> NoiseEstimate:
        if self.tracker_noise is not None:
            return NoiseEstimate(float(self.tracker_noise), "given", True, "the instrument's figure (--noise-mm)")
        if repeats is not None:
            return repeats
        return noise_from_residual(q, residual, n_parameters, structured)

    def _judge_at_fitted_sizes(self, engine, current, notes, factor: float = 2.0) -> bool:
        """Identifiability was judged at typical sizes; an effect fitted at more than ``factor``
        times its typical size is re-judged at its fitted size (RMS of its scaled parameters), so
        that columns too small to resolve at the typical size but not at the fitted one come back."""
        final = engine.evaluate(ordered(current))
        factors, offset = {}, 0
        for e in ordered(current):
            size = final["keep"][e].size
            phi = final["phi"][offset:offset + size]
            offset += size
            if e != "frames" and size and float(np.sqrt(np.mean(phi**2))) > factor:
                factors[e] = float(np.sqrt(np.mean(phi**2)))
        before = {e: tuple(v) for e, v in engine.identify(tuple(ordered(current)))[0].items()}
        if not engine.resize(factors):
            return False
        after = {e: tuple(v) for e, v in engine.identify(tuple(ordered(current)))[0].items()}
        if after != before:
            notes.append("identifiability re-judged at the fitted sizes ("
                         + ", ".join(f"{e} {f:.3g} x typical" for e, f in factors.items())
                         + f"): {sum(len(v) for v in after.values()) - sum(len(v) for v in before.values()):+d} "
                         "parameters")
            return True
        return False



def _relinearise(bases: dict, jacobians: list) -> None:
    """Every effect's TCP sensitivity at the per-part error Jacobians (the frames-only fit's)."""
    for p, jac_x in enumerate(jacobians):
        for b in bases.values():
            b.per_part[p].relinearise(jac_x)
    for b in bases.values():
        b.restack()


def _part_names(effect, part: Part, n_parts: int) -> list[str]:
    """Parameter names of an effect on a part; each measured frame's TCP offset is its own."""
    names = effect.parameter_names()
    if effect.name != "frames" or n_parts == 1:
        return names
    return [n.replace("frames.tool.", f"frames.{part.label}.") for n in names]


def _source_of(measurements) -> str:
    """Where the measurements came from (a MeasurementSet's ``source``; the first frame's of a list)."""
    if isinstance(measurements, (list, tuple)):
        measurements = measurements[0][1]
    return str(getattr(measurements, "source", "the measurements"))


def _first_frame(residual: np.ndarray) -> np.ndarray:
    """The first measured frame's (N, 3) rows of a (N, 3) or (n_parts, N, 3) residual."""
    return residual if residual.ndim == 2 else residual[0]


def _context_table(obs: Observations) -> np.ndarray:
    """(N, c) the context columns that make two rows the same pose (for repeated poses)."""
    cols = [np.asarray(obs.context.payload_kg)[:, None], np.asarray(obs.context.temperature_c)[:, None],
            np.asarray(obs.context.direction)]
    if obs.context.outside_q is not None:
        cols.append(obs.context.outside_q)
    return np.concatenate(cols, axis=1)
