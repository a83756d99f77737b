"""Stage 2: the candidate effects -- every effect of the vocabulary linearised on the measured
poses, which of them can be tried on these data and why not the others, the folds, and the
instrument's noise where the data's own redundancy gives it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...effects import effect_class, make_effect
from ...exceptions import AnalysisError, InputError
from ...frames.noise import NoiseEstimate, noise_from_rigid_frames
from ...model.context import CONTEXT_FIELDS
from ...model.errors import ErrorModel
from ..fitting import FitEngine
from ..bases import EffectBasis, Part, UnionBasis, ordered, position_jacobians
from ..residuals import noise_from_repeats
from ..structure import StructureDetector
from .register import RegisteredMeasurements

#: Noise figure [m per axis] the identifiability test resolves down to a tenth of when the
#: instrument's is not known (a good laser tracker): pruning stays rank-based.
RESOLUTION_NOISE = 2e-5


@dataclass(frozen=True)
class Candidate:
    """One effect of the vocabulary as a candidate: why it was not tried, or its first trial
    (added to frames alone, or to the model it was first tried on). SI units.

    Attributes
    ----------
    effect : str
    tried : bool
    why : str
        Why it was not tried (empty when it was).
    heldout_rms : float or None
        Held-out RMS [m] of the model it was added to, with it.
    gain : float or None
        How much it lowered that model's held-out RMS [m].
    z : float or None
        Paired z of the cut in per-row squared held-out errors.
    n_parameters : int or None
        Its identifiable parameters in that model.
    added_to : tuple of str
        The model it was first tried on, when more than frames alone.
    """

    effect: str
    tried: bool
    why: str = ""
    heldout_rms: float | None = None
    gain: float | None = None
    z: float | None = None
    n_parameters: int | None = None
    added_to: tuple = ()

    def to_dict(self) -> dict:
        if not self.tried:
            return {"tried": False, "why": self.why}
        out = {"tried": True, "heldout_rms_mm_with_frames": self.heldout_rms * 1e3, "gain_mm": self.gain * 1e3,
               "z": self.z, "n_parameters": self.n_parameters}
        if self.added_to:
            out["added_to"] = list(self.added_to)
        return out


def _no_parameter(name: str, robot) -> str:
    """Why an effect has no parameter on ``robot`` (in the words of a candidate left untried)."""
    from ...units import REVOLUTE

    if REVOLUTE not in robot.joint_kinds:
        return f"{name} has no parameter on {robot.name}: its joints are all prismatic, and it acts on revolute ones"
    return f"{name} has no parameter on {robot.name}"


def untried(effect: str, why: str) -> Candidate:
    return Candidate(effect, False, why)


@dataclass(frozen=True)
class CandidateSet:
    """What stage 2 found.

    Attributes
    ----------
    engine : FitEngine
        The fit engine over every buildable effect (it caches the fits the later stages ask for).
    untried : tuple of Candidate
        The effects that cannot be tried, with the reason, in the order they were judged.
    testable : tuple of str
        The effects that can be tried (vocabulary order; not the effects of last resort).
    late_names : tuple of str
        Effects of last resort: built and tried only when the others leave structure.
    stochastic : tuple of str
        Effects of random scatter (tested as extra scatter, never fitted).
    linearised_at : tuple of ndarray
        Per part, the error vector (p_em,) of the frames-only fit, where every effect is linearised
        (:meth:`linearised` gives the error Jacobians there).
    instrument_noise : NoiseEstimate or None
        The instrument's noise from the data's redundancy (rigid frames, base references,
        repeated poses), None when the data have none (or when it is given).
    identifiability_all : dict
        Identifiability of the whole vocabulary in one model (JSON form).
    detector : StructureDetector
        The structure test set up on the main frame's poses.
    notes : tuple of str
    """

    engine: FitEngine
    untried: tuple
    testable: tuple
    late_names: tuple
    stochastic: tuple
    linearised_at: tuple
    instrument_noise: NoiseEstimate | None
    identifiability_all: dict
    detector: StructureDetector
    notes: tuple

    def linearised(self) -> list:
        """Per part, the error Jacobians (N, r, p_em) at the frames-only fit (what late effects are
        linearised at), taken again when asked for: kept, they were 130 MB at 10^5 poses for a step or
        two of the selection that read them."""
        return frames_jacobians(self.engine.parts, self.linearised_at)

    @property
    def bases(self) -> dict:
        """effect -> UnionBasis: every effect built so far (late ones join when tried)."""
        return self.engine.bases


def build_bases(parts: list[Part], names, measured, notes: list, session_labels=(),
                frames_options: dict | None = None) -> tuple[dict, list, list]:
    """Each effect of ``names`` linearised on every part: (bases, the untried candidates, the
    stochastic effects). ``frames_options``: what each session owns (``session_frames``,
    ``session_tools``, see :class:`~tcr_accuracy.effects.frames.Frames`) where there are sessions."""
    bases, rejected, stochastic = {}, [], []
    jacobians = {}  # per part, the error Jacobians at the nominal model and their drive columns: the same for every effect
    for name in names:
        cls = effect_class(name)
        if cls.stochastic:
            stochastic.append(name)
            rejected.append(untried(name, "stochastic: tested as extra scatter, not fitted"))
            continue
        missing = [c for c in cls.context_columns if c in CONTEXT_FIELDS and CONTEXT_FIELDS[c] not in measured]
        if missing and cls.fit_policy.requires_context:
            rejected.append(untried(name, f"needs the {', '.join(missing)} column"))
            continue
        try:
            per_part = []
            for p, part in enumerate(parts):
                options = {"tool_rotation": True} if name == "frames" and part.target_rotation is not None else {}
                if name == "frames" and len(session_labels) > 1:
                    options["sessions"] = tuple(session_labels)
                    options.update(frames_options or {})
                options.update(cls.fit_policy.options_for_data(part.robot, part.q, part.context))
                effect = make_effect(name, part.robot, **options)
                if effect.n_params == 0:  # e.g. a gear's cyclic error on a robot of prismatic joints only
                    raise InputError(_no_parameter(name, part.robot))
                labels = _part_names(effect, part, len(parts))
                em = ErrorModel(part.robot)
                if p not in jacobians:
                    jac_x = position_jacobians(part.robot, part.q, None,
                                               part.orientation_weight if part.target_rotation is not None else None)
                    jacobians[p] = (jac_x, np.ascontiguousarray(jac_x[:, :, em.drive_slice]))
                per_part.append(EffectBasis(effect, part, em, jacobians[p][0], labels, jac_q=jacobians[p][1]))
            basis = UnionBasis(per_part)
        except InputError as exc:
            rejected.append(untried(name, f"not testable on these data: {exc}"))
            continue
        if basis.nonlinearity > 1e-6:
            notes.append(f"{name} is nonlinear in its parameters (relative {basis.nonlinearity:.1e}); "
                         "it is fitted in its linearisation about zero")
        bases[name] = basis
    return bases, rejected, stochastic


def relinearise(bases: dict, jacobians) -> None:
    """Every effect's TCP sensitivity at the per-part error Jacobians (the frames-only fit's)."""
    for p, jac_x in enumerate(jacobians):
        jac_q = None  # the drive columns of jac_x, one copy shared by the effects held as factors
        for b in bases.values():
            if jac_q is None:
                jac_q = np.ascontiguousarray(jac_x[:, :, b.per_part[p].basis.drive_slice])
            b.per_part[p].relinearise(jac_x, jac_q)
    for b in bases.values():
        b.restack()


def frames_fit_point(parts, frames) -> list:
    """Per part, the error vector (p_em,) of the frames-only fit: where the effects are linearised
    (the sessions' frames and TCP offsets differ a little: their mean)."""
    pre = FitEngine(parts, {"frames": frames}, [], rank_tol=0.0)
    columns = pre.columns(["frames"])
    phi, _ = pre.fit(columns, np.arange(parts[0].q.shape[0]))
    out = []
    for p in range(len(parts)):
        basis, _, idx = columns.per_part[p]
        out.append(basis.errors(phi[idx] * columns.scale[idx]).mean(axis=0))
    return out


def frames_jacobians(parts, x_frames) -> list:
    """Per part, the error Jacobians (N, r, p_em) at its error vector x_frames[p] (p_em,)."""
    return [position_jacobians(part.robot, part.q, x, part.orientation_weight if part.target_rotation is not None
                               else None) for part, x in zip(parts, x_frames)]


def identifiable_alone(engine: FitEngine, name: str) -> bool:
    """Whether an effect keeps any identifiable parameter next to frames alone."""
    return engine.kept(("frames", name))[name].size > 0


NOT_IDENTIFIABLE = "no identifiable parameter on these data (beyond frames)"


def build_candidates(registered: RegisteredMeasurements, names, *, folds: int, rank_tol: float,
                     tracker_noise: float | None, rng: np.random.Generator, fold_repeats: int = 1,
                     instrument=None, frames_options: dict | None = None) -> CandidateSet:
    """Stage 2 of the diagnosis.

    Parameters
    ----------
    registered : RegisteredMeasurements
        Stage 1's result.
    names : list of str
        The effects to consider (vocabulary order, ``frames`` included).
    folds : int
        k of the k-fold cross-validation.
    fold_repeats : int
        How many fold assignments (repeated k-fold): held-out errors are their mean.
    instrument : Instrument or None
        The instrument's specification: its noise where the data's redundancy gives none.
    rank_tol : float
        Identifiability tolerance on normalised pivots.
    tracker_noise : float or None
        The instrument's per-axis noise [m] when given (then not estimated).
    rng : numpy.random.Generator
        Draws the fold split, then the structure test's neighbours and permutations.
    frames_options : dict or None
        What each session owns (:mod:`.setup`); None: a tracker frame each (the default of
        :class:`~tcr_accuracy.effects.frames.Frames`).
    """
    from sklearn.model_selection import RepeatedKFold

    parts = list(registered.parts)
    n = registered.n_rows
    notes: list = []
    # an effect of last resort is built only if it is tried (its maps are the largest: tens of MB per 10^4 poses)
    late_names = [e for e in names if effect_class(e).fit_policy.last_resort]
    bases, rejected, stochastic = build_bases(parts, [e for e in names if e not in late_names],
                                              registered.measured_context, notes, registered.session_labels,
                                              frames_options)
    if "frames" not in bases:
        raise AnalysisError("the frames effect could not be built")
    order = ordered(bases)
    # a TCP offset of centimetres changes which directions duplicate one another:
    # linearise about the frames-only fit, not the nominal model
    linearised_at = frames_fit_point(parts, bases["frames"])
    relinearise(bases, frames_jacobians(parts, linearised_at))
    kfold = RepeatedKFold(n_splits=folds, n_repeats=fold_repeats, random_state=int(rng.integers(2**31 - 1)))
    every = [(np.asarray(a), np.asarray(b)) for a, b in kfold.split(np.arange(n))]
    split = [every[r * folds:(r + 1) * folds] for r in range(fold_repeats)]
    # the instrument's noise from the data's own redundancy: reflectors on one rigid body, else repeated poses
    redundancy = None
    if tracker_noise is None:
        main = registered.measurements
        redundancy = noise_from_rigid_frames([p.position for p in registered.nominal],
                                             [f.measurements.position for f in registered.frames],
                                             [f.label for f in registered.frames]) or registered.reference_noise or \
            noise_from_repeats(main.q, main.position, _context_table(parts[0]))
        if redundancy is None and instrument is not None:
            points = np.concatenate([f.measurements.position for f in registered.frames])
            redundancy = NoiseEstimate(instrument.per_axis_noise(points), "instrument specification", True,
                                       instrument.describe() + "; per point from its distance, the RMS over the "
                                       "measured points")
    resolution = tracker_noise or (redundancy.per_axis if redundancy else RESOLUTION_NOISE)
    engine = FitEngine(parts, bases, split, rank_tol, min_motion=0.1 * resolution)
    _, identifiability_all = engine.identify(order)
    testable = []
    for name in order:
        if name == "frames":
            continue
        if identifiable_alone(engine, name):
            testable.append(name)
        else:
            rejected.append(untried(name, NOT_IDENTIFIABLE))
    detector = StructureDetector(registered.measurements.q, rng, kinds=registered.robot.joint_kinds)
    return CandidateSet(engine=engine, untried=tuple(rejected), testable=tuple(testable),
                        late_names=tuple(late_names), stochastic=tuple(stochastic), linearised_at=tuple(linearised_at),
                        instrument_noise=redundancy, identifiability_all=identifiability_all, detector=detector,
                        notes=tuple(notes))


def _part_names(effect, part: Part, n_parts: int) -> list[str]:
    """Parameter names of an effect on a part; each measured frame's TCP offset is its own."""
    names = effect.parameter_names()
    if effect.name != "frames" or n_parts == 1:
        return names
    return [n.replace("frames.tool.", f"frames.{part.label}.") for n in names]


def _context_table(part: Part) -> np.ndarray:
    """(N, c) the context columns that make two rows the same pose (for repeated poses)."""
    context = part.context
    cols = [np.asarray(context.payload_kg)[:, None], np.asarray(context.temperature_c)[:, None],
            np.asarray(context.direction)]
    if context.outside_q is not None:
        cols.append(context.outside_q)
    return np.concatenate(cols, axis=1)
