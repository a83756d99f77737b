"""Poses chosen for the prediction: Bayesian I-, G- and D-optimal designs on the effect vocabulary.

The robot's error at a pose is, to first order, ``e(q) = G(q) theta``: the columns ``G`` (3 x P)
of every effect of the vocabulary that a pose's joint values drive (geometry, compliance, scale,
gear and cyclic errors), each parameter at its typical size (the effect class's
``parameter_scales``), so ``theta`` is dimensionless. What is known of ``theta`` before a
measurement is its prior: the geometric effects (``frames``, ``joint_offsets``, ``geometry``) free
(a flat prior), every other effect's parameters normal with standard deviation ``tau_e`` typical
sizes (``tau_e = 1`` from nothing; from measurements, the ``tau_e`` and the noise that make
them most probable, :func:`fit_prior`: type-II maximum likelihood, with the geometric parameters
integrated out). The posterior covariance after poses with columns ``G`` at noise ``sigma`` is
``S = (G^T G / sigma^2 + Lambda)^-1`` (``Lambda`` the prior precision), and the variance of the
prediction at a pose ``x`` is ``g_x S g_x^T``:

* **I-optimal** (the default): the poses that most reduce the prediction variance averaged over
  where the robot will work (a task: given poses, the poses in a box, or the joint ranges),
  ``trace(W S)`` with ``W`` the task's mean ``g_x^T g_x``;
* **G-optimal**: the largest prediction variance over the task (greedily: the mean over the
  task poses whose variance is largest at each step);
* **D-optimal**: ``log det S^-1``, all parameters at once (the classical calibration design).

The prior makes the design Bayesian: an effect that is typically a few micrometres at the TCP
takes few poses, one that the measurements show is large takes more, and directions no pose can
determine cost nothing. Greedy exchange-free selection, one pose at a time: with ``H_c = w_c S``
(``w_c = g_c / sigma``) held for every candidate, adding pose ``b`` updates ``S`` by a rank-3
Woodbury step and every candidate's ``H_c``, ``Q_c = I + H_c w_c^T`` and ``V_c = H_c W H_c^T``
by products of order ``3 M P``, so a step over 10,000 candidates and 500 parameters takes a
fraction of a second (the reduction of ``trace(W S)`` by a candidate is ``trace(Q_c^-1 V_c)``,
its D-gain ``log det Q_c``).

Hand-written: the greedy Bayesian designs are a few lines of linear algebra on our own effect
columns (no design library takes a prior information matrix with per-effect precisions and a
task-weighted criterion; scikit-learn's ``ARDRegression`` estimates one precision per
*parameter*, not per effect, and gives no design).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg
from scipy.optimize import minimize

from ..effects import effect_class, make_effect
from ..exceptions import InputError
from ..model.context import MeasurementContext
from ..model.errors import ErrorModel
from ..model.robot import JointLimitWarning, RobotModel
from .bases import EffectBasis, Part, ordered, position_jacobians

#: Prior precision of a geometric parameter, per typical size squared: flat in effect (a standard
#: deviation of 1000 typical sizes, 0.2 m for a joint placement), yet the information stays
#: invertible where no pose moves a combination of them (a redundant base and joint offset).
FLAT_PRECISION = 1e-6

#: The context the design can be measured in: an effect reading the approach direction, the
#: temperature or the time is not a function of the pose (the order handles drift).
DESIGNABLE_CONTEXT = {"payload_kg"}

#: Bounds of the fitted prior scales tau_e [typical sizes] and of the noise [m].
TAU_BOUNDS = (1e-2, 1e2)
NOISE_BOUNDS_M = (1e-7, 1e-2)

#: Noise per axis [m] assumed without measurements and without ``noise_m`` (a laser tracker).
DEFAULT_NOISE_M = 2e-5

#: A greedy design recomputes its candidates' products from the information once the task's mean
#: variance has fallen below this fraction of what it was at the last recomputation.
REFRESH = 0.1

#: Poses of the task whose largest variances a G-optimal step averages (the greedy surrogate of the maximum).
G_WORST = 10

#: Most task poses a G-optimal design follows pose by pose (a random subset of a larger task).
G_TASK_MAX = 2000


def design_vocabulary(effects=None) -> list[str]:
    """The effects a design can be made for, in vocabulary order: not stochastic, and driven by the
    joint values (and the payload) only. ``effects``: restrict to these (``frames`` always in)."""
    from ..effects import vocabulary

    names = vocabulary() if effects is None else ordered(set(effects) | {"frames"})
    out = []
    for name in names:
        cls = effect_class(name)
        if cls.stochastic or not set(cls.context_columns) <= DESIGNABLE_CONTEXT:
            continue
        out.append(name)
    return out


@dataclass(frozen=True)
class DesignColumns:
    """The TCP position sensitivity of every parameter of a design vocabulary at N poses.

    Attributes
    ----------
    g : ndarray of shape (N, 3, P)
        d(TCP position)/d(parameter) times the parameter's typical size [m].
    owner : ndarray of shape (P,)
        The effect each column belongs to.
    effects : list of str
        The effects, vocabulary order.
    """

    g: np.ndarray
    owner: np.ndarray
    effects: list

    @property
    def n_parameters(self) -> int:
        return int(self.g.shape[2])


def design_columns(robot: RobotModel, q, effects, *, payload_kg: float = 0.0,
                   context: MeasurementContext | None = None) -> DesignColumns:
    """The columns of ``effects`` (see :func:`design_vocabulary`) at joint values q (N, n_joints) [rad, m],
    measured with ``payload_kg`` [kg] (or in the rows' ``context``)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if context is None:
        context = MeasurementContext.defaults(len(q), robot.n_joints, payload_kg=payload_kg)
    part = Part(robot, q, np.zeros((len(q), 3)), context, robot.tool_frame)
    em = ErrorModel(robot)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", JointLimitWarning)
        jac_x = position_jacobians(robot, q)
    blocks, owner = [], []
    for name in ordered(effects):
        basis = EffectBasis(make_effect(name, robot), part, em, jac_x)
        g = np.asarray(basis.g[:, :3, :] * basis.scales)
        blocks.append(g)
        owner += [name] * g.shape[2]
    return DesignColumns(np.concatenate(blocks, axis=2), np.array(owner), list(ordered(effects)))


def nonzero_effects(columns: DesignColumns) -> list[str]:
    """The effects whose columns move the TCP at some pose (a compliance without payload and ... may not)."""
    moves = np.abs(columns.g).max(axis=(0, 1)) > 0
    return [e for e in columns.effects if moves[columns.owner == e].any()]


def _flat(name: str) -> bool:
    cls = effect_class(name)
    return bool(cls.geometric or cls.family == "setup")


@dataclass(frozen=True)
class EffectPrior:
    """What is known of the parameters before the next poses.

    Attributes
    ----------
    tau : dict
        Effect name -> prior standard deviation of its parameters, in typical sizes (the geometric
        effects are flat and absent).
    noise_m : float
        Measurement noise per axis [m] (plus what the vocabulary leaves, when fitted).
    fitted : bool
        Whether tau and the noise were fitted to measurements (:func:`fit_prior`) or are the typical sizes.
    n_poses : int
        The poses it was fitted to (0: none).
    """

    tau: dict
    noise_m: float
    fitted: bool = False
    n_poses: int = 0

    def precision(self, owner) -> np.ndarray:
        """(P,) prior precision of each column of ``owner`` [1 / typical size^2]."""
        return np.array([FLAT_PRECISION if _flat(e) else 1.0 / self.tau.get(e, 1.0) ** 2 for e in owner])

    def to_dict(self) -> dict:
        return {"tau_typical_sizes": {e: float(v) for e, v in self.tau.items()}, "noise_mm": self.noise_m * 1e3,
                "fitted": self.fitted, "n_poses": self.n_poses}


def typical_prior(effects, noise_m: float | None = None) -> EffectPrior:
    """Every non-geometric effect of ``effects`` at its typical size (tau = 1): the prior of a first campaign."""
    return EffectPrior({e: 1.0 for e in effects if not _flat(e)},
                       DEFAULT_NOISE_M if noise_m is None else float(noise_m))


class _Gram:
    """Sufficient statistics of a least-squares problem: G^T G (P, P), G^T y (P,), y^T y and the row count."""

    def __init__(self, g: np.ndarray, y: np.ndarray):
        flat = g.reshape(-1, g.shape[2])
        self.gtg = flat.T @ flat
        self.gty = flat.T @ y.reshape(-1)
        self.yty = float(y.reshape(-1) @ y.reshape(-1))
        self.rows = flat.shape[0]


def _cholesky(information: np.ndarray):
    """scipy's Cholesky factor of a posterior information matrix (P, P). Columns of very different sizes
    (a base translation of 10 mm against a 50 urad gear harmonic) and flat directions no pose moves leave
    it positive definite in exact arithmetic but not always in rounding: a jitter of 1e-13, then 1e-11 ...
    of its mean diagonal is added until the factor exists."""
    jitter = 0.0
    scale = float(np.mean(np.diag(information)))
    for _ in range(8):
        try:
            return linalg.cho_factor(information + jitter * np.eye(len(information)), check_finite=False)
        except linalg.LinAlgError:
            jitter = scale * (1e-13 if jitter == 0.0 else jitter / scale * 100)
    raise linalg.LinAlgError("the posterior information is not positive definite")


def _posterior_mean(gram: _Gram, precision: np.ndarray, noise_m: float):
    """(theta (P,), Cholesky factor of the posterior information) at prior ``precision`` and noise."""
    beta = 1.0 / noise_m**2
    information = beta * gram.gtg + np.diag(precision)
    factor = _cholesky(information)
    return linalg.cho_solve(factor, beta * gram.gty, check_finite=False), factor


def fit_prior(columns: DesignColumns, errors: np.ndarray, *, noise_m: float | None = None) -> EffectPrior:
    """The prior scales and noise the measured errors make most probable (type-II maximum likelihood).

    The errors are modelled as ``G theta + noise``, the geometric parameters flat, each other
    effect's parameters normal with standard deviation ``tau_e`` typical sizes; the evidence
    ``p(errors | tau, sigma)`` is maximised over ``log tau_e`` (within :data:`TAU_BOUNDS`) and
    ``log sigma`` (unless ``noise_m`` is given) by L-BFGS-B on its analytic gradient (Bishop, *Pattern
    Recognition and Machine Learning*, 3.5; the per-effect form of automatic relevance determination).

    Parameters
    ----------
    columns : DesignColumns
        At the measured poses (N, 3, P).
    errors : ndarray of shape (N, 3)
        Measured minus nominal TCP position in the robot's base frame [m].
    noise_m : float, optional
        Hold the noise at this [m] (per axis) instead of fitting it.

    Returns
    -------
    EffectPrior
        Fitted; the noise includes what the vocabulary cannot express.
    """
    g, owner = columns.g, columns.owner
    errors = np.asarray(errors, dtype=float)
    if errors.shape != (g.shape[0], 3):
        raise InputError(f"fit_prior: errors of shape {errors.shape}, expected ({g.shape[0]}, 3)")
    gram = _Gram(g, errors)
    effects = [e for e in columns.effects if not _flat(e)]
    members = [owner == e for e in effects]
    flat = np.array([_flat(e) for e in owner])
    fixed_noise = noise_m is not None

    def unpack(h):
        sigma = float(noise_m) if fixed_noise else float(np.exp(h[0]))
        taus = np.exp(h[0 if fixed_noise else 1:])
        precision = np.full(len(owner), FLAT_PRECISION)
        for tau, member in zip(taus, members):
            precision[member] = 1.0 / tau**2
        return sigma, precision

    def objective(h):
        sigma, precision = unpack(h)
        beta = 1.0 / sigma**2
        theta, factor = _posterior_mean(gram, precision, sigma)
        inverse = linalg.cho_solve(factor, np.eye(len(owner)), check_finite=False)
        residual = gram.yty - 2 * theta @ gram.gty + theta @ gram.gtg @ theta
        log_det = 2 * np.sum(np.log(np.diag(factor[0])))
        value = 0.5 * (beta * residual + precision @ theta**2 + log_det - np.sum(np.log(precision[~flat]))
                       + gram.rows * np.log(sigma**2))
        per_column = 1.0 - precision * (theta**2 + np.diag(inverse))  # d value / d log tau, per column
        gradient = [float(np.sum(per_column[member])) for member in members]
        if not fixed_noise:  # d value / d log sigma
            gradient.insert(0, float(gram.rows - beta * (residual + np.sum(inverse * gram.gtg))))
        return float(value), np.array(gradient)

    start = [] if fixed_noise else [np.log(max(np.sqrt(gram.yty / max(gram.rows, 1)) / 3, 2 * NOISE_BOUNDS_M[0]))]
    start += [0.0] * len(effects)
    bounds = ([] if fixed_noise else [tuple(np.log(NOISE_BOUNDS_M))]) + [tuple(np.log(TAU_BOUNDS))] * len(effects)
    if not bounds:
        return EffectPrior({}, float(noise_m), fitted=True, n_poses=int(g.shape[0]))
    found = minimize(objective, np.array(start), jac=True, method="L-BFGS-B", bounds=bounds)
    h = found.x
    sigma = float(noise_m) if fixed_noise else float(np.exp(h[0]))
    taus = np.exp(h[0 if fixed_noise else 1:])
    return EffectPrior({e: float(t) for e, t in zip(effects, taus)}, sigma, fitted=True, n_poses=int(g.shape[0]))


class BayesianErrorModel:
    """The posterior of the linearised vocabulary: the errors a prior and measured poses predict, with their spread.

    Fitted in closed form (one Cholesky factor of the P x P information ``A = G^T G / sigma^2 + Lambda``):
    the posterior mean ``theta = A^-1 G^T y / sigma^2`` and covariance ``S = A^-1`` (Bishop, *Pattern
    Recognition and Machine Learning*, 3.3). What the learning curve of :func:`learning_curve` refits on every
    subsample, and what ``predict --method bayes`` (:class:`~tcr_accuracy.prediction.bayesian.BayesianCalibration`)
    predicts with.

    Attributes (after :meth:`fit`)
    ------------------------------
    theta_ : ndarray of shape (P,)
        Posterior mean [typical sizes].
    factor_ : tuple
        scipy's Cholesky factor of the posterior information (``cho_factor`` form).
    """

    def __init__(self, prior: EffectPrior):
        self.prior = prior

    def fit(self, columns: DesignColumns, errors: np.ndarray) -> "BayesianErrorModel":
        """Fit to columns (N, 3, P) and errors (N, 3) [m]; returns self."""
        gram = _Gram(columns.g, np.asarray(errors, dtype=float))
        self.theta_, self.factor_ = _posterior_mean(gram, self.prior.precision(columns.owner), self.prior.noise_m)
        return self

    @property
    def covariance_(self) -> np.ndarray:
        """(P, P) posterior covariance ``S`` of the parameters [typical sizes^2]."""
        return linalg.cho_solve(self.factor_, np.eye(len(self.theta_)), check_finite=False)

    def _whitened(self, g_flat: np.ndarray) -> np.ndarray:
        """(P, R) ``C^-1 g^T`` for rows g (R, P), ``C`` the Cholesky factor (``A = C C^T``): its columns' inner
        products are ``g S g^T``."""
        c, lower = self.factor_
        return linalg.solve_triangular(c, g_flat.T, lower=lower, trans="N" if lower else "T", check_finite=False)

    def predict(self, columns: DesignColumns, return_std: bool = False, chunk: int = 2048):
        """(M, 3) predicted errors [m] at the poses of ``columns``; with ``return_std``, also the posterior
        predictive standard deviation of a measurement there per axis (M, 3) [m]:
        ``sqrt(diag(g S g^T) + sigma^2)``, the parameters' spread plus the prior's noise (which, fitted, holds
        what the vocabulary leaves)."""
        mean = columns.g @ self.theta_
        if not return_std:
            return mean
        p = columns.g.shape[2]
        variance = np.empty(mean.shape)
        for start in range(0, len(mean), chunk):
            block = columns.g[start:start + chunk]
            whitened = self._whitened(block.reshape(-1, p))
            variance[start:start + chunk] = np.sum(whitened**2, axis=0).reshape(-1, 3)
        return mean, np.sqrt(variance + self.prior.noise_m**2)

    def leave_one_out(self, columns: DesignColumns, errors: np.ndarray) -> np.ndarray:
        """(N, 3) leave-one-pose-out residuals [m] at the poses it was fitted to, the prior held: the error of
        pose i minus what the model fitted without it predicts there, ``(I - H_ii)^-1 r_i`` with ``r_i`` the
        fitted residual and ``H_ii = g_i S g_i^T / sigma^2`` the pose's 3 x 3 block of the hat matrix
        (exact for a linear model with a fixed prior)."""
        errors = np.asarray(errors, dtype=float)
        n, _, p = columns.g.shape
        residual = errors - self.predict(columns)
        whitened = self._whitened(columns.g.reshape(-1, p)).T.reshape(n, 3, -1)
        hat = np.einsum("nip,njp->nij", whitened, whitened) / self.prior.noise_m**2
        return np.linalg.solve(np.eye(3) - hat, residual[:, :, None])[:, :, 0]


@dataclass
class Design:
    """K poses chosen for the prediction, and what they are expected to do.

    Attributes
    ----------
    picked : ndarray of shape (K,)
        Indices into the candidates, in the order chosen.
    criterion : str
        ``I``, ``G`` or ``D``.
    gain_per_pose : ndarray of shape (K,)
        Each pick's gain at its turn (I and G: prediction variance removed [m^2]; D: nats).
    task_std_before_m, task_std_after_m : float
        RMS over the task poses of the prediction's standard deviation (3D) [m], with the measured
        poses only and with the design added (linearised model, the prior's noise).
    task_worst_std_before_m, task_worst_std_after_m : float
        The largest over the task poses [m].
    log_det_gain : float
        log det of the posterior information with the design minus without [nats].
    """

    picked: np.ndarray
    criterion: str
    gain_per_pose: np.ndarray
    task_std_before_m: float
    task_std_after_m: float
    task_worst_std_before_m: float
    task_worst_std_after_m: float
    log_det_gain: float
    notes: list = field(default_factory=list)


def _task_variances(g_task: np.ndarray, s: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """(T,) trace of the 3 x 3 prediction covariance g S g^T at each task pose [m^2]."""
    out = np.empty(g_task.shape[0])
    for start in range(0, g_task.shape[0], chunk):
        block = g_task[start:start + chunk]
        out[start:start + chunk] = np.einsum("tip,tip->t", block @ s, block)
    return out


def task_variance(measured: DesignColumns | None, task: DesignColumns, prior: EffectPrior) -> float:
    """Mean over the task poses of the prediction's posterior variance (3D, the trace of its 3 x 3
    covariance) [m^2] after the ``measured`` poses (None: the prior alone); what :meth:`LearningCurve.predict`
    turns into an expected held-out error."""
    p = task.g.shape[2]
    information = np.diag(prior.precision(task.owner))
    if measured is not None and measured.g.shape[0]:
        flat = measured.g.reshape(-1, p)
        information += (flat.T @ flat) / prior.noise_m**2
    covariance = linalg.cho_solve(_cholesky(information), np.eye(p), check_finite=False)
    return float(np.mean(_task_variances(task.g, covariance)))


def plan_design(measured: DesignColumns | None, candidates: DesignColumns, task: DesignColumns, prior: EffectPrior,
                k: int, *, criterion: str = "I", rng: np.random.Generator | None = None, progress=None) -> Design:
    """Choose k of the candidate poses, greedily, for the prediction over the task poses.

    Parameters
    ----------
    measured : DesignColumns or None
        The poses measured so far (N, 3, P); None for a first campaign.
    candidates : DesignColumns
        Poses the robot can take and the tracker can see (M, 3, P), same effects.
    task : DesignColumns
        Where the robot will work (T, 3, P), same effects (may be ``candidates`` itself).
    prior : EffectPrior
    k : int
        Poses to choose (at most M).
    criterion : {"I", "G", "D"}, default="I"
    rng : numpy.random.Generator, optional
        Draws the task subset a G-optimal design follows when the task has more than
        :data:`G_TASK_MAX` poses.
    progress : callable(int), optional
        Called with 1 after each pose chosen (a progress bar's update).

    Returns
    -------
    Design
    """
    if criterion not in ("I", "G", "D"):
        raise InputError(f"criterion {criterion!r}: choose I, G or D")
    m, p = candidates.g.shape[0], candidates.g.shape[2]
    if not 1 <= k <= m:
        raise InputError(f"-k {k}: choose between 1 and the {m} candidates")
    beta = 1.0 / prior.noise_m**2
    information = np.diag(prior.precision(candidates.owner))
    if measured is not None and measured.g.shape[0]:
        flat = measured.g.reshape(-1, p)
        information += beta * (flat.T @ flat)
    s = linalg.cho_solve(_cholesky(information), np.eye(p), check_finite=False)
    s = (s + s.T) / 2
    start_log_det = np.linalg.slogdet(information)[1]
    g_task = task.g
    if criterion == "G" and g_task.shape[0] > G_TASK_MAX:
        g_task = g_task[np.sort((rng or np.random.default_rng(0)).choice(g_task.shape[0], G_TASK_MAX, replace=False))]
    task_flat = g_task.reshape(-1, p)
    weight = task_flat.T @ task_flat / g_task.shape[0]  # W: the task's mean g^T g [m^2]
    variance_before = _task_variances(g_task, s)
    root_beta = np.sqrt(beta)
    def fresh(s):
        """H, Q, V (and the task's H) from S anew: the rank-3 downdates subtract numbers up to the flat
        prior's 1e6 typical sizes squared, and rounding would swamp the gains once the variance has
        fallen by orders of magnitude."""
        h = (candidates.g.reshape(-1, p) @ s).reshape(m, 3, p) * root_beta  # H_c = w_c S
        q = np.eye(3) + np.matmul(h, candidates.g.transpose(0, 2, 1)) * root_beta  # I + w_c S w_c^T
        v = np.matmul(h @ weight, h.transpose(0, 2, 1)) if criterion == "I" else None  # w_c S W S w_c^T
        h_task = (task_flat @ s).reshape(g_task.shape[0], 3, p) if criterion == "G" else None
        return h, q, v, h_task, float(np.sum(weight * s))

    h, q, v, h_task, refreshed_at = fresh(s)
    available = np.ones(m, dtype=bool)
    picked, gains = [], []
    for _ in range(k):
        if float(np.sum(weight * s)) < REFRESH * refreshed_at:
            s = linalg.cho_solve(_cholesky(information), np.eye(p), check_finite=False)
            h, q, v, h_task, refreshed_at = fresh(s)
        if criterion == "D":
            gain = np.linalg.slogdet(q)[1]
        else:
            if criterion == "G":  # the task poses of largest variance now, as one small task
                worst = np.argsort(np.einsum("tip,tip->t", h_task, g_task))[-G_WORST:]
                cross = np.matmul(h, g_task[worst].reshape(-1, p).T)  # (M, 3, 3 G_WORST): w_c S g_t^T
                v = np.matmul(cross, cross.transpose(0, 2, 1)) / len(worst)
            gain = np.einsum("nij,nji->n", np.linalg.inv(q), v)
        gain[~available] = -np.inf
        best = int(np.argmax(gain))
        picked.append(best)
        gains.append(float(gain[best]))
        available[best] = False
        # rank-3 Woodbury step: S <- S - u Qb^-1 u^T with u = S w_b^T; every candidate's H, Q, V follow
        u = s @ candidates.g[best].T * root_beta  # (P, 3)
        r = np.linalg.solve(q[best], u.T)  # Qb^-1 u^T (3, P)
        c = np.matmul(h, candidates.g[best].T) * root_beta  # w_c S w_b^T (M, 3, 3)
        if criterion == "I":
            hwr = np.matmul(h, weight @ r.T)  # w_c S W r^T (M, 3, 3)
            v = (v - np.matmul(c, hwr.transpose(0, 2, 1)) - np.matmul(hwr, c.transpose(0, 2, 1))
                 + np.matmul(c @ (r @ weight @ r.T), c.transpose(0, 2, 1)))
        q = q - np.matmul(c @ np.linalg.inv(q[best]), c.transpose(0, 2, 1))
        h -= np.matmul(c, r[None])
        if h_task is not None:
            h_task -= np.matmul(np.matmul(h_task, candidates.g[best].T) * root_beta, r[None])
        s = s - u @ r
        information = information + beta * candidates.g[best].T @ candidates.g[best]
        if progress is not None:
            progress(1)
    s = linalg.cho_solve(_cholesky(information), np.eye(p), check_finite=False)
    variance_after = _task_variances(g_task, s)
    log_det = np.linalg.slogdet(information)[1]
    return Design(picked=np.array(picked, dtype=int), criterion=criterion, gain_per_pose=np.array(gains),
                  task_std_before_m=float(np.sqrt(np.mean(variance_before))),
                  task_std_after_m=float(np.sqrt(np.mean(np.maximum(variance_after, 0)))),
                  task_worst_std_before_m=float(np.sqrt(np.max(variance_before))),
                  task_worst_std_after_m=float(np.sqrt(np.max(np.maximum(variance_after, 0)))),
                  log_det_gain=float(log_det - start_log_det))


@dataclass(frozen=True)
class LearningCurve:
    """Held-out error against the number of measured poses, from subsamples, and what the model expects.

    Each subsample of ``sizes[i]`` measured poses fits :class:`BayesianErrorModel` (the prior held) and is
    scored on the poses it left out: ``rms_m[i]`` is the RMS of the 3D miss over the repeats. Beside it,
    what the model itself expects there, ``expected_rms_m[i]``: the root of 3 sigma^2 (a measured
    point's own noise) plus the posterior variance v of the prediction at the left-out poses. The
    subsamples' squared misses are regressed on the two, ``a 3 sigma^2 + b v`` (non-negative least
    squares; a = b = 1 for a model that is right): the model's calibration. An extrapolation -- the
    error with more poses -- is the model's expectation ``3 sigma^2 + v`` at the posterior variance those
    poses leave; its interval is what ``a 3 sigma^2 + b v`` gives over bootstrap resamples of the
    subsamples, widened to hold the expectation. (On the UR5, 60 random poses, four seeds, the expectation
    put the gain of 140 more poses at 0.71-1.30 x what measuring them gave, and the regressed (a, b) at
    0.62-1.09 x: a few dozen subsamples determine a and b too loosely to replace the model.) The
    expectation, not a power law fitted to a few noisy points, carries the extrapolation: it knows which
    parameters the next poses determine.

    Attributes
    ----------
    sizes : ndarray of shape (S,)
        Training sizes [poses].
    rms_m, low_m, high_m : ndarray of shape (S,)
        RMS held-out 3D miss at each size [m], and the 5-95 % range over the repeats.
    expected_rms_m : ndarray of shape (S,)
        What the model expects at each size [m].
    noise_weight, variance_weight : float
        a and b of the calibration.
    boot : ndarray of shape (B, 2)
        (a, b) over bootstrap resamples of the subsamples.
    noise_floor_m : float
        sqrt(3) x the prior's noise per axis [m] (the instrument and what the vocabulary leaves): no number
        of poses predicts better than this against a measured point.
    """

    sizes: np.ndarray
    rms_m: np.ndarray
    low_m: np.ndarray
    high_m: np.ndarray
    expected_rms_m: np.ndarray
    noise_weight: float
    variance_weight: float
    boot: np.ndarray
    noise_floor_m: float

    def _rms(self, a, b, variance_m2):
        return np.sqrt(np.maximum(a * self.noise_floor_m**2 + b * variance_m2, 0.0))

    @staticmethod
    def _held(expected: float, boot: np.ndarray) -> tuple[float, float, float]:
        low, high = np.quantile(boot, [0.05, 0.95])
        return float(expected), float(min(low, expected)), float(max(high, expected))

    def predict(self, variance_m2: float) -> tuple[float, float, float]:
        """(expected, 5 %, 95 %) held-out RMS miss [m] where the prediction's mean posterior variance (3D) is
        ``variance_m2`` [m^2] (:attr:`Design.task_std_before_m` squared, or after): the model's own
        expectation, its interval what the subsamples' calibration (bootstrapped) allows, widened to hold it."""
        boot = self._rms(self.boot[:, 0], self.boot[:, 1], variance_m2)
        return self._held(self._rms(1.0, 1.0, variance_m2), boot)

    def gain(self, variance_now_m2: float, variance_then_m2: float) -> tuple[float, float, float]:
        """(expected, 5 %, 95 %) drop of the held-out RMS miss [m] from one posterior variance to another."""
        a, b = self.boot[:, 0], self.boot[:, 1]
        boot = self._rms(a, b, variance_now_m2) - self._rms(a, b, variance_then_m2)
        return self._held(self._rms(1.0, 1.0, variance_now_m2) - self._rms(1.0, 1.0, variance_then_m2), boot)

    @property
    def floor_m(self) -> float:
        """The held-out RMS miss no number of poses goes below [m]: sqrt(3) x the noise per axis."""
        return float(self.noise_floor_m)

    def to_dict(self) -> dict:
        return {"sizes": [int(n) for n in self.sizes], "heldout_rms_mm": (self.rms_m * 1e3).tolist(),
                "heldout_rms_5_mm": (self.low_m * 1e3).tolist(), "heldout_rms_95_mm": (self.high_m * 1e3).tolist(),
                "expected_rms_mm": (self.expected_rms_m * 1e3).tolist(), "noise_weight": self.noise_weight,
                "variance_weight": self.variance_weight, "floor_mm": self.floor_m * 1e3,
                "noise_floor_mm": self.noise_floor_m * 1e3}


#: Fewest measured poses a learning curve is drawn from (its smallest subsample is half of them).
LEARNING_CURVE_MIN_POSES = 20


def learning_curve(columns: DesignColumns, errors: np.ndarray, prior: EffectPrior, rng: np.random.Generator, *,
                   n_sizes: int = 5, repeats: int = 8, n_boot: int = 400, progress=None) -> LearningCurve:
    """The held-out error of :class:`BayesianErrorModel` on subsamples of the measured poses, and the model's
    own expectation there.

    Parameters
    ----------
    columns : DesignColumns
        At the N measured poses (N, 3, P).
    errors : ndarray of shape (N, 3)
        Measured minus nominal TCP position, base frame [m].
    prior : EffectPrior
        Held for every subsample (fitted once on all N poses).
    rng : numpy.random.Generator
        Draws the subsamples and the bootstrap.
    n_sizes, repeats, n_boot : int
        Training sizes (geometric, from N/2 to 4N/5), subsamples per size, bootstrap resamples.
    progress : callable(int), optional
        Called with 1 after each size.

    Returns
    -------
    LearningCurve

    Raises
    ------
    InputError
        Fewer than :data:`LEARNING_CURVE_MIN_POSES` poses.
    """
    n = columns.g.shape[0]
    if n < LEARNING_CURVE_MIN_POSES:
        raise InputError(f"{n} measured poses: a learning curve needs at least {LEARNING_CURVE_MIN_POSES}")
    errors = np.asarray(errors, dtype=float)
    p = columns.g.shape[2]
    precision = prior.precision(columns.owner)
    full = _Gram(columns.g, errors)
    noise3 = 3.0 * prior.noise_m**2
    sizes = np.unique(np.round(np.geomspace(n / 2, 0.8 * n, n_sizes)).astype(int))
    observed = np.empty((len(sizes), repeats))
    expected = np.empty((len(sizes), repeats))
    for i, size in enumerate(sizes):
        for r in range(repeats):
            test = np.sort(rng.choice(n, n - size, replace=False))
            left_out = _Gram(columns.g[test], errors[test])  # the fit's statistics: all minus the left-out
            gram = _Gram.__new__(_Gram)  # the posterior mean reads G^T G and G^T y only
            gram.gtg, gram.gty = full.gtg - left_out.gtg, full.gty - left_out.gty
            theta, factor = _posterior_mean(gram, precision, prior.noise_m)
            g_test = columns.g[test].reshape(-1, p)
            miss = errors[test] - g_test.dot(theta).reshape(-1, 3)
            observed[i, r] = float(np.mean(np.sum(miss**2, axis=1)))
            covariance = linalg.cho_solve(factor, np.eye(p), check_finite=False)
            expected[i, r] = float(np.sum((g_test @ covariance) * g_test)) / len(test)  # the posterior variance
        if progress is not None:
            progress(1)
    flat_observed, flat_variance = observed.ravel(), expected.ravel()
    weights = _calibration(flat_observed, flat_variance, noise3)
    boot = np.empty((n_boot, 2))
    for b in range(n_boot):
        pick = rng.integers(0, flat_observed.size, flat_observed.size)
        boot[b] = _calibration(flat_observed[pick], flat_variance[pick], noise3)
    rms = np.sqrt(observed)
    return LearningCurve(sizes=sizes, rms_m=np.sqrt(observed.mean(axis=1)), low_m=np.quantile(rms, 0.05, axis=1),
                         high_m=np.quantile(rms, 0.95, axis=1),
                         expected_rms_m=np.sqrt(noise3 + expected.mean(axis=1)),
                         noise_weight=weights[0], variance_weight=weights[1], boot=boot,
                         noise_floor_m=float(np.sqrt(noise3)))


def _calibration(observed: np.ndarray, variance: np.ndarray, noise3: float) -> tuple[float, float]:
    """(a, b) >= 0 of observed mean squared miss = a 3 sigma^2 + b variance, least squares (scipy's nnls):
    how much of the noise and of the posterior variance the held-out misses show."""
    from scipy.optimize import nnls

    scale = float(np.mean(observed)) or 1.0
    design = np.column_stack([np.full_like(variance, noise3), variance]) / scale
    if np.ptp(variance) <= 1e-9 * max(float(np.mean(variance)), 1e-300):  # one variance: one ratio
        ratio = float(np.sum(observed) / np.sum(noise3 + variance))
        return ratio, ratio
    coefficients, _ = nnls(design, observed / scale)
    return float(coefficients[0]), float(coefficients[1])


@dataclass(frozen=True)
class StopAdvice:
    """Whether measuring more poses is worth it.

    Attributes
    ----------
    stop : bool
    reason : str
        Why, in words with the figures [mm].
    now_m, then_m : tuple of float
        (expected, 5 %, 95 %) held-out RMS miss [m] over the task with the poses measured and after the next ones.
    gain_m : tuple of float
        (expected, 5 %, 95 %) drop [m].
    """

    stop: bool
    reason: str
    now_m: tuple
    then_m: tuple
    gain_m: tuple


def stop_advice(curve: LearningCurve, design: "Design", *, min_gain_m: float | None) -> StopAdvice:
    """Stop when the expected drop of the held-out error over the task from measuring the ``design``'s poses is
    below ``min_gain_m`` [m], or when the error with the poses measured is within 5 % of the noise floor."""
    before, after = design.task_std_before_m**2, design.task_std_after_m**2
    now, then, gain = curve.predict(before), curve.predict(after), curve.gain(before, after)
    more = len(design.picked)
    words = (f"measuring the {more} poses would take the held-out RMS error over the task from {now[0] * 1e3:.4f} mm to "
             f"{then[0] * 1e3:.4f} mm [{then[1] * 1e3:.4f}, {then[2] * 1e3:.4f}] (gain {gain[0] * 1e3:.4f} mm "
             f"[{gain[1] * 1e3:.4f}, {gain[2] * 1e3:.4f}], 90 % interval)")
    floor = curve.floor_m
    if now[0] <= 1.05 * floor:
        return StopAdvice(True, f"stop: the noise floor is reached ({now[0] * 1e3:.4f} mm against "
                                f"{floor * 1e3:.4f} mm); {words}", now, then, gain)
    if min_gain_m is not None and gain[0] < min_gain_m:
        return StopAdvice(True, f"stop: {words}, below the limit of {min_gain_m * 1e3:g} mm", now, then, gain)
    if min_gain_m is None:
        return StopAdvice(False, f"expected: {words} (no limit given to stop at)", now, then, gain)
    return StopAdvice(False, f"continue: {words}, above the limit of {min_gain_m * 1e3:g} mm", now, then, gain)


def campaign_order(q: np.ndarray, n_references: int, rng: np.random.Generator) -> tuple[np.ndarray, int, float]:
    """An order to measure poses q (K, n_joints) in, with a reference pose repeated through it.

    The poses are put in an order no joint follows (:func:`separating_order`),
    so a drift in time cannot pass for an error growing with a joint; the reference (the pose nearest
    the middle of the others in joint space) is measured ``n_references`` times, first, last and
    evenly between, so the drift and the repeatability are seen directly.

    Returns
    -------
    rows : ndarray of shape (K + n_references - 1,) or (K,)
        Indices into q, the reference's index appearing ``n_references`` times (once when 0 or 1).
    reference : int
        The reference's index into q.
    largest_r : float
        The largest |correlation| of a joint with the place in the order, the repeats left out.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if len(q) < 2:
        return np.zeros(max(int(n_references), 1) if len(q) else 0, dtype=int), 0, 0.0
    spread = np.std(q, axis=0)
    spread[np.ptp(q, axis=0) == 0] = 1.0  # a joint that never moves: its std is rounding (1e-17), not 0
    reference = int(np.argmin(np.sum(((q - q.mean(axis=0)) / spread) ** 2, axis=1)))
    others = np.array([i for i in range(len(q)) if i != reference], dtype=int)
    order, largest_r = separating_order(q[others], rng)
    rows = list(others[order])
    repeats = max(int(n_references), 1)
    if repeats == 1:
        return np.array([reference] + rows, dtype=int), reference, largest_r
    # the reference at the first and last place and evenly between
    places = np.round(np.linspace(0, len(rows), repeats)).astype(int)
    out = []
    for i, place in enumerate(places):
        previous = 0 if i == 0 else places[i - 1]
        out += rows[previous:place] + [reference]
    return np.array(out, dtype=int), reference, largest_r


def separating_order(q: np.ndarray, rng: np.random.Generator, tries: int = 256) -> tuple[np.ndarray, float]:
    """An order to measure poses q (N, n_joints) in so that no joint's angle follows the order:
    of ``tries`` random permutations, the one whose largest |correlation| between a joint's value
    and the row's place is smallest. Measured so, a drift in time (a warm-up, a tracker that moves)
    cannot pass for an error that grows with a joint (an encoder scale), nor the reverse.

    Returns
    -------
    order : ndarray of shape (N,)
        Row indices of q in the order to measure them.
    largest_r : float
        The largest |correlation| of a joint with the place in that order.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = q.shape[0]
    moving = np.ptp(q, axis=0) > 0  # not std > 0: a still joint's std is rounding, and 0 again on its copy
    if n < 3 or not moving.any():
        return np.arange(n), 0.0
    centred = (q[:, moving] - q[:, moving].mean(axis=0)) / q[:, moving].std(axis=0)
    # the place's mean needs no subtracting: each centred column sums to zero
    place = np.arange(n) / np.std(np.arange(n))
    best, best_r = np.arange(n), float(np.max(np.abs(place @ centred / n)))
    for _ in range(tries):
        order = rng.permutation(n)
        r = float(np.max(np.abs(place @ centred[order] / n)))
        if r < best_r:
            best, best_r = order, r
    return best, best_r
