"""Which poses to measure next: a D- (or Ds-) optimal design on the identification Jacobian,
or a T-optimal one that tells rival fitted models apart.

Effects the measured poses cannot tell apart (an ambiguity group of the diagnosis) become
separable where their TCP motions differ: outside the joint range the data covered, or
at combinations of joints it missed. Given the poses already measured and the effects to
separate, :func:`plan_poses` picks K candidate configurations that add the most
information about all their parameters together: greedy D-optimal design, each step
taking the candidate that maximises log det(M + G_c^T G_c), where M is the Fisher
information (J^T J of the columns at their typical sizes) of the poses so far and G_c the
candidate's 3 x P block. With M^-1 known, the gain of every candidate is
log det(I_3 + G_c M^-1 G_c^T) (matrix determinant lemma) and M^-1 is updated by Woodbury,
so a step costs one batched 3 x 3 determinant per candidate. To separate rival effects (an
ambiguity group), the criterion is, summed over the rivals, the information about each
one's parameters beyond what all the others absorb (Ds-optimality). When the rival models
are fitted already, :func:`plan_discriminating_poses` goes straight for what a test between
them sees: the poses where one model's prediction differs most from the best the other can
do after refitting (T-optimality, Atkinson and Fedorov), the refit updated pose by pose by
recursive least squares.

Hand-written: FIGAROH and Kalibrot design geometric calibration poses for their own
parameterisations; neither takes the compliance, gear and scale effects of this
project's vocabulary or a prior information matrix from poses already measured, and the
greedy update is a few lines of numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..analysis.reachable import PoseFilter, draw_poses
from ..effects import effect_class
from ..effects.compose import predict_positions
from ..exceptions import InputError
from ..model.context import MeasurementContext
from ..model.robot import RobotModel
from .bases import ordered
from .bayes_design import design_columns, separating_order  # noqa: F401 (separating_order: its home moved)


@dataclass
class PosePlan:
    """K suggested joint configurations and how much they add.

    q : (K, n_joints) [rad, m], in the order they were picked
    effects : the effects whose parameters the design is for
    separate : the rival effects it is to tell apart (Ds-optimal), or empty
    n_parameters : columns of the design
    log_det_gain : log det of the information with the plan minus without (nats)
    gain_per_pose : (K,) what each pick added at its turn
    resolved_before / resolved_after : how many independent parameter combinations the
        measurements determine to better than their typical size at the given noise
        (eigenvalues of the information above noise^2), before and after the plan
    """

    q: np.ndarray
    effects: list
    n_parameters: int
    log_det_gain: float
    gain_per_pose: np.ndarray
    resolved_before: int
    resolved_after: int
    separate: list


def _design_columns(robot: RobotModel, q: np.ndarray, effects: list, context: MeasurementContext
                    ) -> tuple[np.ndarray, list]:
    """(N, 3, P) TCP position sensitivity of every parameter of ``effects`` (vocabulary order) at
    its typical size, and the effect each column belongs to."""
    columns = design_columns(robot, q, effects, context=context)
    return columns.g, list(columns.owner)


class _Information:
    """Fisher information J^T J of a set of columns (plus a ridge) and its inverse, grown
    pose by pose: the gain of adding a pose's 3 rows is log det(I + G M^-1 G^T)
    (matrix determinant lemma), the inverse follows by Woodbury."""

    def __init__(self, g_measured: np.ndarray, ridge: float):
        p = g_measured.shape[2]
        flat = g_measured.reshape(-1, p)
        self.info = flat.T @ flat + ridge * np.eye(p)
        self.inv = np.linalg.inv(self.info)

    def gains(self, g: np.ndarray) -> np.ndarray:
        # G M^-1 G^T per candidate as two BLAS products (a three-operand einsum summed p and q in plain loops:
        # 17 minutes of CPU for 3000 candidates of the UR5's vocabulary)
        projected = np.matmul((g.reshape(-1, g.shape[2]) @ self.inv).reshape(g.shape), g.transpose(0, 2, 1))
        return np.linalg.slogdet(np.eye(3) + projected)[1]

    def add(self, block: np.ndarray) -> None:
        middle = np.linalg.inv(np.eye(3) + block @ self.inv @ block.T)
        self.inv = self.inv - self.inv @ block.T @ middle @ block @ self.inv
        self.info = self.info + block.T @ block


def candidate_configurations(robot: RobotModel, n: int, rng: np.random.Generator) -> np.ndarray:
    """Up to n configurations (n, n_joints) the robot can take: drawn uniformly within the joint
    limits (+-pi where a revolute joint has none), ``<mimic>`` joints on their rule, free of
    self-collision where the URDF has collision geometry -- the filter
    (:class:`~tcr_accuracy.analysis.reachable.PoseFilter`) ``plan-poses`` and ``simulate`` use.
    A prismatic joint without limits cannot be drawn and is an input error."""
    return draw_poses(PoseFilter.for_robot(robot), n, rng).q


def _candidates_and_context(robot, k, candidates, n_candidates, payload_kg, rng):
    """The candidate configurations (given, or :func:`candidate_configurations`) checked against k,
    and the context the poses will be measured in (the payload, no other conditions)."""
    if k < 1:
        raise InputError(f"-k {k}: need at least one pose")
    if candidates is None:
        candidates = candidate_configurations(robot, n_candidates, rng if rng is not None else np.random.default_rng(0))
    if len(candidates) < k:
        raise InputError(f"{len(candidates)} candidate configurations for -k {k}: need at least k")

    def context(n):
        return MeasurementContext.defaults(n, robot.n_joints, payload_kg=payload_kg)

    return candidates, context


def plan_poses(robot: RobotModel, measured_q: np.ndarray, effects, k: int, *, separate=None,
               candidates: np.ndarray | None = None, n_candidates: int = 3000, payload_kg: float = 0.0,
               noise_m: float = 2e-5, rng: np.random.Generator | None = None) -> PosePlan:
    """Choose k configurations among ``candidates`` (default: ``n_candidates`` the robot can
    take, :func:`candidate_configurations`) that, added to the poses ``measured_q`` (N, n)
    [rad, m], best determine the parameters of ``effects`` (``frames`` is always included).

    separate : effects to tell apart from one another (the members of ambiguity groups, the
        chosen one included): the design then maximises, summed over these effects, the
        information about each one's parameters *beyond what all the other effects can
        absorb* (log det M - log det M_without_it, the Schur complement: Ds-optimality),
        each term divided by the effect's parameter count so that a large effect does not
        drown a small one -- what a paired test between the rival models can see. None:
        D-optimal for all parameters.
    payload_kg : the payload the new poses will be measured with (compliance's torques).
    noise_m : measurement noise per axis [m], for counting the resolved parameter combinations.
    """
    effects = ordered(set(effects) | {"frames"} | set(separate or ()))
    stochastic = [e for e in effects if effect_class(e).stochastic]
    if stochastic:
        raise InputError(f"{', '.join(stochastic)}: stochastic effects have no parameters to design for")
    candidates, context = _candidates_and_context(robot, k, candidates, n_candidates, payload_kg, rng)

    g_measured, owner = _design_columns(robot, measured_q, effects, context(len(measured_q)))
    g_cand, _ = _design_columns(robot, candidates, effects, context(len(candidates)))
    p = g_cand.shape[2]
    # directions no pose so far moves: a small ridge keeps M invertible; its size (1e-6 of the
    # mean diagonal, a typical-size parameter seen through a micrometre) leaves the ranking of
    # candidates that do move them unaffected
    ridge = 1e-6 * max(float(np.sum(g_measured**2)) / p,
                       float(np.mean(np.sum(g_cand**2, axis=(0, 1)))))
    full = _Information(g_measured, ridge)
    owner = np.array(owner)
    rivals = []  # (columns without the effect, its tracker, its parameter count)
    for effect in ordered(set(separate or ())):
        without = owner != effect
        if without.all() or not without.any():
            continue
        rivals.append((without, _Information(g_measured[:, :, without], ridge), int(np.sum(~without))))

    def resolved(information):
        return int(np.sum(np.linalg.eigvalsh(information - ridge * np.eye(information.shape[0])) > noise_m**2))

    resolved_before = resolved(full.info)
    start_logdet = np.linalg.slogdet(full.info)[1]
    available = np.ones(len(candidates), dtype=bool)
    picked, gains = [], []
    for _ in range(k):
        if rivals:
            whole = full.gains(g_cand)
            gain = sum((whole - tracker.gains(g_cand[:, :, cols])) / size for cols, tracker, size in rivals)
        else:
            gain = full.gains(g_cand)
        gain[~available] = -np.inf
        best = int(np.argmax(gain))
        picked.append(best)
        gains.append(float(gain[best]))
        available[best] = False
        full.add(g_cand[best])
        for cols, tracker, _ in rivals:
            tracker.add(g_cand[best][:, cols])
    return PosePlan(q=candidates[picked], effects=effects, n_parameters=p,
                    log_det_gain=float(np.linalg.slogdet(full.info)[1] - start_logdet), gain_per_pose=np.array(gains),
                    resolved_before=resolved_before, resolved_after=resolved(full.info), separate=list(separate or []))


class _Discrepancy:
    """One rival model R refitted (linearised, columns at typical sizes) to the predictions
    of another, T: the squared discrepancy R cannot absorb grows by r^T S^-1 r when a pose
    with residual r = d - G theta and S = I + G M^-1 G^T is added (recursive least squares).

    With candidates (``track``), it holds every candidate's H = G M^-1, S and residual and updates
    them by the rank-3 Woodbury step of each added pose (order 3 M P a step, not 3 M P^2)."""

    def __init__(self, g_measured: np.ndarray, d_measured: np.ndarray, ridge: float):
        self.information = _Information(g_measured, ridge)
        self.theta = self.information.inv @ np.einsum("nip,ni->p", g_measured, d_measured)
        self.total = float(np.sum((d_measured - np.einsum("nip,p->ni", g_measured, self.theta)) ** 2))
        self.g = self.d = None

    def track(self, g: np.ndarray, d: np.ndarray) -> None:
        """Follow the candidates' columns g (M, 3, P) and discrepancies d (M, 3) from here on."""
        self.g, self.d = g, d
        self.h = (g.reshape(-1, g.shape[2]) @ self.information.inv).reshape(g.shape)
        self.s = np.eye(3) + np.matmul(self.h, g.transpose(0, 2, 1))
        self.residual = d - g @ self.theta

    def gains(self, g: np.ndarray | None = None, d: np.ndarray | None = None) -> np.ndarray:
        if g is None:  # the tracked candidates
            g, d, residual, s = self.g, self.d, self.residual, self.s
        else:
            residual = d - g @ self.theta
            s = np.eye(3) + np.matmul((g.reshape(-1, g.shape[2]) @ self.information.inv).reshape(g.shape),
                                      g.transpose(0, 2, 1))
        return np.einsum("ni,ni->n", residual, np.linalg.solve(s, residual[:, :, None])[:, :, 0])

    def add(self, g: np.ndarray, d: np.ndarray, index: int | None = None) -> None:
        inv = self.information.inv
        s = np.eye(3) + g @ inv @ g.T
        residual = d - g @ self.theta
        self.total += float(residual @ np.linalg.solve(s, residual))
        gain = inv @ g.T @ np.linalg.inv(s)
        self.theta = self.theta + gain @ residual
        if self.g is not None:
            s_inv = np.linalg.inv(s)
            cross = np.matmul(self.h, g.T)  # G_c M^-1 g_b^T (M, 3, 3)
            self.residual -= np.einsum("nij,j->ni", cross, s_inv @ residual)
            self.s -= np.matmul(cross @ s_inv, cross.transpose(0, 2, 1))
            self.h -= np.matmul(cross, (s_inv @ (inv @ g.T).T)[None])
        self.information.add(g)


def plan_discriminating_poses(robot: RobotModel, measured_q: np.ndarray, rivals, k: int, *,
                              candidates: np.ndarray | None = None, n_candidates: int = 3000,
                              payload_kg: float = 0.0, noise_m: float = 2e-5,
                              rng: np.random.Generator | None = None, progress=None) -> np.ndarray:
    """Choose k configurations (among ``candidates``, default :func:`candidate_configurations`) where
    rival fitted models disagree in a way neither can fit away: greedy T-optimal design.

    rivals : list of pairs of fitted models, each model (effect instances, parameter
        vectors [SI]) as :meth:`GapDiagnosis.fitted_model` gives it. For each pair, both
        ways round, the refitted model's share of the other's prediction is removed on the
        poses so far (linearised at typical sizes) and the candidate that adds most squared
        discrepancy is taken. Pairs are balanced: a candidate's worth is the sum over pairs and
        directions of log(1 + its added discrepancy / the discrepancy so far, at least
        noise_m^2), so a pair that is already far apart does not take every pose.
    progress : callable(int), optional; called with 1 after each pose chosen.
    Returns (k, n_joints) joint values [rad, m].
    """
    candidates, context = _candidates_and_context(robot, k, candidates, n_candidates, payload_kg, rng)
    measured_q = np.asarray(measured_q, dtype=float)
    if measured_q.size == 0:
        raise InputError("plan_discriminating_poses: measured_q holds no pose; the rival models are told apart "
                         "beyond what refitting them on the measured poses absorbs: pass the poses they were "
                         "fitted on", parameter="measured_q")
    trackers = []
    for model_a, model_b in rivals:
        for truth, refit in ((model_a, model_b), (model_b, model_a)):
            names = [e.name for e in refit[0]]
            d_meas = (predict_positions(robot, *truth, measured_q, context(len(measured_q)))
                      - predict_positions(robot, *refit, measured_q, context(len(measured_q))))
            d_cand = (predict_positions(robot, *truth, candidates, context(len(candidates)))
                      - predict_positions(robot, *refit, candidates, context(len(candidates))))
            g_meas, _ = _design_columns(robot, measured_q, names, context(len(measured_q)))
            g_cand, _ = _design_columns(robot, candidates, names, context(len(candidates)))
            ridge = 1e-6 * max(float(np.sum(g_meas**2)) / g_meas.shape[2], 1e-300)
            tracker = _Discrepancy(g_meas, d_meas, ridge)
            tracker.track(g_cand, d_cand)
            trackers.append(tracker)
    if not trackers:
        raise InputError("plan_discriminating_poses: no rival models given")
    available = np.ones(len(candidates), dtype=bool)
    picked = []
    for _ in range(k):
        gain = sum(np.log1p(t.gains() / max(t.total, noise_m**2)) for t in trackers)
        gain[~available] = -np.inf
        best = int(np.argmax(gain))
        picked.append(best)
        available[best] = False
        for t in trackers:
            t.add(t.g[best], t.d[best])
        if progress is not None:
            progress(1)
    return candidates[picked]
