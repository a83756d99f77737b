"""Which error matters: one-at-a-time sweeps, Sobol indices and tolerance allocation.

Three views of the same question, from local to global:

* **Sweeps** (the seed's control-variable method, its Fig. 7-9 and 13-16): one error
  source at a time is set to a list of signed values, every other source at zero, and
  the TCP position and attitude errors are recorded. Exact (no linearisation).
* **Sobol indices**: variance-based global sensitivity of the TCP error to every random
  input at once (the sources of an :class:`~tcr_accuracy.errors.ErrorBudget`, or the
  d, s, theta, w_x, w_y of each joint of a
  :class:`~tcr_accuracy.clearance.ClearanceModel`), first order S1 and total ST with
  bootstrap confidence intervals, from SALib (Saltelli sampling; Saltelli 2010 estimator
  for S1, Jansen for ST). SALib samples the unit hypercube; each column is mapped through
  the input's inverse CDF (:meth:`ErrorSource.ppf`), so any distribution works.
* **Tolerance allocation**: the largest factor by which all spreads (or those of some
  groups) can be multiplied while ``P(|dP| < T) >= p`` still holds, found by root
  finding on a Monte Carlo with common random numbers (the same uniform draws for every
  factor), so the answer is a deterministic function of the seed.

Outputs are named as in :mod:`tcr_accuracy.montecarlo`: ``dx, dy, dz`` (base frame
[m]), ``norm`` (|dP| [m]), ``d_alpha_z, d_beta_y, d_gamma_x`` (ZYX Euler angle errors
[rad]) and ``rotation_angle`` (the angle of the attitude error [rad]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .errors import ErrorBudget, ErrorModel, ErrorSource, link_length_direction
from .exceptions import AnalysisError, InputError
from .jacobians import error_jacobian
from .kinematics import pose_error, tcp_poses
from .robot import REVOLUTE, RobotModel

#: Output columns of sweeps and Sobol indices (SI units: m then rad).
OUTPUTS = ("dx", "dy", "dz", "norm", "d_alpha_z", "d_beta_y", "d_gamma_x", "rotation_angle")
OUTPUT_UNITS = ("m", "m", "m", "m", "rad", "rad", "rad", "rad")

#: The seed's sweep values: link lengths +-0.02, 0.04, 0.06 mm (Fig. 7) [m] ...
SEED_LINK_SWEEP = np.array([-0.06, -0.04, -0.02, 0.0, 0.02, 0.04, 0.06]) * 1e-3
#: ... and joint angles +-0.02 .. 0.1 deg (Fig. 8, 9) [rad].
SEED_ANGLE_SWEEP = np.radians(np.array([-0.1, -0.08, -0.06, -0.04, -0.02, 0.0,
                                        0.02, 0.04, 0.06, 0.08, 0.1]))


def _error_columns(robot: RobotModel, q: np.ndarray, x: np.ndarray, error_model: ErrorModel,
                   nominal=None) -> np.ndarray:
    """(N, 8) columns OUTPUTS of the TCP error for error vectors x (N, n_params) at q."""
    nominal = nominal if nominal is not None else tcp_poses(robot, q)
    err = pose_error(nominal, tcp_poses(robot, q, x, error_model))
    return np.column_stack([err.position, err.position_norm, err.euler_zyx, err.rotation_angle])


# ---------------------------------------------------------------------------------------
# One-at-a-time sweeps
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepResult:
    """TCP errors when each source alone takes each value.

    Attributes
    ----------
    source_names : list of str, length n_sources
    values : ndarray of shape (n_values,)
        The signed values every source was set to [unit].
    unit : str
        Unit of ``values`` (``m`` or ``rad``).
    errors : ndarray of shape (n_sources, n_values, 8)
        Columns :data:`OUTPUTS` [m, rad].
    """

    source_names: list[str]
    values: np.ndarray
    unit: str
    errors: np.ndarray

    def output(self, name: str) -> np.ndarray:
        """(n_sources, n_values) one output column."""
        return self.errors[:, :, OUTPUTS.index(name)]


def sweep(robot: RobotModel, q: np.ndarray, sources: Sequence[tuple[str, np.ndarray]],
          values: np.ndarray, unit: str, error_model: ErrorModel | None = None) -> SweepResult:
    """Set each source alone to each value and record the exact TCP error.

    Parameters
    ----------
    robot : RobotModel
    q : ndarray of shape (n_joints,)
        Joint values [rad, m].
    sources : sequence of (name, direction (n_params,)) pairs
        The error vector of source k at value v is ``v * direction_k``.
    values : ndarray of shape (n_values,)
        Signed values [unit].
    unit : str
        ``m`` or ``rad``, for reports.
    """
    error_model = error_model or ErrorModel(robot)
    values = np.asarray(values, dtype=float)
    if not sources:
        raise InputError("sweep: no error sources to sweep")
    directions = np.stack([d for _, d in sources])  # (n_sources, n_params)
    x = (directions[:, None, :] * values[None, :, None]).reshape(-1, error_model.size)
    cols = _error_columns(robot, q, x, error_model)
    return SweepResult([n for n, _ in sources], values, unit,
                       cols.reshape(len(sources), values.size, len(OUTPUTS)))


def link_length_sources(robot: RobotModel, error_model: ErrorModel) -> list[tuple[str, np.ndarray]]:
    """(name, direction) of a unit length error of every link with a length.

    Named ``l1`` .. after the joint the link ends at, as in the seed's Table 2 (l_j is
    the offset of joint j's origin from the previous joint).
    """
    out = []
    for j in range(robot.n_joints):
        direction = link_length_direction(robot, j, error_model)
        if direction is not None:
            out.append((f"l{j + 1}", direction))
    return out


def drive_sources(robot: RobotModel, error_model: ErrorModel, kind: str = REVOLUTE
                  ) -> list[tuple[str, np.ndarray]]:
    """(name, direction) of a unit drive error of every joint of one kind."""
    out = []
    for name, k in zip(robot.joint_names, robot.joint_kinds):
        if k == kind:
            d = error_model.zeros()
            d[error_model.index(f"{name}.drive")] = 1.0
            out.append((name, d))
    return out


def seed_sweeps(robot: RobotModel, q: np.ndarray, link_values: np.ndarray = SEED_LINK_SWEEP,
                angle_values: np.ndarray = SEED_ANGLE_SWEEP) -> dict[str, SweepResult]:
    """The seed's Fig. 7 (link lengths) and Fig. 8-9 (joint angles) sweeps at q."""
    em = ErrorModel(robot)
    return {
        "link_length": sweep(robot, q, link_length_sources(robot, em), link_values, "m", em),
        "joint_angle": sweep(robot, q, drive_sources(robot, em), angle_values, "rad", em),
    }


# ---------------------------------------------------------------------------------------
# Clearance sweeps (the seed's Fig. 13-16)
# ---------------------------------------------------------------------------------------
#: Clearance offsets swept: -0.5 .. 0.5 mm, one Table 4 standard deviation of s [m].
CLEARANCE_OFFSET_SWEEP = np.linspace(-0.5e-3, 0.5e-3, 11)
#: Clearance deflections swept: -0.087 .. 0.087 rad, one Table 4 standard deviation of w.
CLEARANCE_DEFLECTION_SWEEP = np.linspace(-0.087, 0.087, 11)

#: Clearance quantities swept one at a time: (key, ClearanceSample field, angle theta or None, unit).
CLEARANCE_QUANTITIES = (
    ("axial", "axial", None, "m"),  # axial movement d along the joint axis
    ("radial_u", "radial", 0.0, "m"),  # clearance rod s at theta = 0 (along u)
    ("radial_v", "radial", 0.5 * math.pi, "m"),  # clearance rod s at theta = 90 deg (along v)
    ("deflection_u", "deflection_u", None, "rad"),  # axis tilt w_x about u
    ("deflection_v", "deflection_v", None, "rad"),  # axis tilt w_y about v
)


def clearance_sweeps(model, q: np.ndarray, offsets: np.ndarray = CLEARANCE_OFFSET_SWEEP,
                     deflections: np.ndarray = CLEARANCE_DEFLECTION_SWEEP) -> dict[str, SweepResult]:
    """One clearance quantity of one joint at a time, through the clearance model's own map.

    Parameters
    ----------
    model : :class:`~tcr_accuracy.clearance.ClearanceModel`
        Which joints have play and how a play displaces the joint placement.
    q : ndarray of shape (n_joints,) [rad, m]
    offsets : ndarray of shape (n_offsets,)
        Values of the axial movement d and of the radial rod s [m].
    deflections : ndarray of shape (n_deflections,)
        Values of the deflections w_x, w_y [rad].

    Returns
    -------
    dict with keys ``axial``, ``radial_u``, ``radial_v``, ``deflection_u``,
    ``deflection_v``; each a SweepResult over the joints with play (named after them).
    """
    from .clearance import ClearanceSample

    robot, em = model.robot, model.error_model
    k = len(model.joints)
    nominal = tcp_poses(robot, q)
    out = {}
    for key, field_name, theta, unit in CLEARANCE_QUANTITIES:
        values = np.asarray(offsets if unit == "m" else deflections, dtype=float)
        m = values.size
        errors = np.empty((k, m, len(OUTPUTS)))
        for idx in range(k):
            parts = {f: np.zeros((m, k)) for f in ("axial", "radial", "angle", "deflection_u", "deflection_v")}
            parts[field_name][:, idx] = values
            if theta is not None:
                parts["angle"][:, idx] = theta
            x = model.to_parameters(ClearanceSample(**parts))
            errors[idx] = _error_columns(robot, q, x, em, nominal)
        out[key] = SweepResult([robot.joint_names[j] for j in model.joints], values, unit, errors)
    return out


# ---------------------------------------------------------------------------------------
# Independent random inputs of a sampler (error budget or clearance model)
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RandomInputs:
    """The independent scalar random inputs behind a sampler and their map to x.

    Attributes
    ----------
    sources : list of ErrorSource
        One per input: name, group, unit and distribution (``ppf``, ``variance``).
        Their ``direction`` is only meaningful when ``matrix`` is not None.
    scalable : ndarray of shape (n_inputs,), bool
        Whether a tolerance factor scales the input (a clearance angle theta does not).
    to_parameters : callable, (N, n_inputs) values -> (N, n_params) error vectors
    matrix : ndarray of shape (n_params, n_inputs) or None
        The linear map when x = matrix @ values (error budgets); None otherwise.
    error_model : ErrorModel
    sampler : the ErrorBudget or ClearanceModel they come from
    """

    sources: list[ErrorSource]
    scalable: np.ndarray
    to_parameters: Callable[[np.ndarray], np.ndarray]
    matrix: np.ndarray | None
    error_model: ErrorModel
    sampler: object

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.sources]

    @property
    def groups(self) -> list[str]:
        return [s.group for s in self.sources]

    def values_from_unit(self, u: np.ndarray) -> np.ndarray:
        """Map uniform draws u (N, n_inputs) in (0, 1) to input values (N, n_inputs).

        Column k goes through input k's inverse CDF; u is clipped away from 0 and 1
        so that unbounded distributions stay finite.
        """
        u = np.clip(np.asarray(u, dtype=float), 1e-12, 1.0 - 1e-12)
        return np.column_stack([s.ppf(u[:, k]) for k, s in enumerate(self.sources)])

    def scaled_sampler(self, factor: float, groups: set[str] | None):
        """The sampler with the spreads of ``groups`` (None: all) multiplied by factor."""
        if isinstance(self.sampler, ErrorBudget):
            return self.sampler.scaled(factor, groups)
        spreads = {}
        for group, key in (("axial", "axial_std"), ("radial", "radial_std"), ("deflection", "deflection_std")):
            if groups is None or group in groups:
                spreads[key] = getattr(self.sampler, key) * factor
        return self.sampler.with_spreads(**spreads)


def random_inputs(sampler) -> RandomInputs:
    """The independent inputs of an ErrorBudget or a ClearanceModel."""
    if isinstance(sampler, ErrorBudget):
        a = sampler.matrix
        return RandomInputs(list(sampler.sources), np.ones(len(sampler.sources), bool),
                            lambda values: values @ a.T, a, sampler.error_model, sampler)
    from .clearance import ClearanceModel, ClearanceSample

    if not isinstance(sampler, ClearanceModel):
        raise InputError(f"no sensitivity analysis for {type(sampler).__name__} (need an error budget "
                         "or a clearance model)")
    em, zero = sampler.error_model, np.zeros(sampler.error_model.size)
    sources, scalable = [], []
    fields = (("axial d", "axial", "m", sampler.axial_std), ("radial s", "radial", "m", sampler.radial_std),
              ("radial angle", "radial_angle", "rad", None),
              ("deflection w_x", "deflection", "rad", sampler.deflection_std),
              ("deflection w_y", "deflection", "rad", sampler.deflection_std))
    for j in sampler.joints:
        for label, group, unit, std in fields:
            name = f"{sampler.robot.joint_names[j]} {label}"
            if std is None:  # theta: uniform on [0, 2 pi)
                sources.append(ErrorSource(name, group, zero, unit, "uniform", low=0.0, high=2.0 * math.pi))
            else:
                sources.append(ErrorSource(name, group, zero, unit, "normal", std=std))
            scalable.append(std is not None)
    k = len(sampler.joints)

    def to_parameters(values: np.ndarray) -> np.ndarray:
        v = values.reshape(values.shape[0], k, 5)
        return sampler.to_parameters(ClearanceSample(axial=v[..., 0], radial=v[..., 1], angle=v[..., 2],
                                                     deflection_u=v[..., 3], deflection_v=v[..., 4]))

    return RandomInputs(sources, np.array(scalable), to_parameters, None, em, sampler)


# ---------------------------------------------------------------------------------------
# Sobol indices (SALib)
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SobolIndices:
    """Variance-based sensitivity of the TCP error to the random inputs of a sampler.

    Attributes
    ----------
    source_names, groups : list of str, length n_inputs
    outputs : tuple of str, length n_outputs (subset of :data:`OUTPUTS`)
    first_order, first_order_conf, total_order, total_order_conf : ndarray of shape
        (n_outputs, n_inputs). NaN for an output whose variance is zero.
    variance : ndarray of shape (n_outputs,)
        Variance of each output over the Sobol sample [m^2 or rad^2].
    linear_share : ndarray of shape (3, n_inputs)
        First-order (Jacobian) prediction of S1 for dx, dy, dz: ``(J a_k)^2 var_k``
        over its sum; equal to S1 when the TCP error is linear in the inputs. NaN for
        samplers that are not linear in their inputs (clearance).
    n_base : int
        SALib's base sample size N; the model was evaluated N (n_inputs + 2) times.
    conf_level : float
    """

    source_names: list[str]
    groups: list[str]
    outputs: tuple[str, ...]
    first_order: np.ndarray
    first_order_conf: np.ndarray
    total_order: np.ndarray
    total_order_conf: np.ndarray
    variance: np.ndarray
    linear_share: np.ndarray
    n_base: int
    conf_level: float

    @property
    def n_evaluations(self) -> int:
        return self.n_base * (len(self.source_names) + 2)

    def ranking(self, output: str = "norm") -> list[int]:
        """Input indices by decreasing total index ST for one output."""
        k = self.outputs.index(output)
        return [int(i) for i in np.argsort(-np.nan_to_num(self.total_order[k], nan=-1.0), kind="stable")]


def linear_variance_shares(inputs: RandomInputs, q: np.ndarray) -> np.ndarray:
    """(3, n_inputs) first-order variance share of each input in dx, dy, dz.

    From Pinocchio's error Jacobian J (3 position rows, n_params): input k moves the
    TCP by ``J a_k`` per unit, so its variance contribution is ``(J a_k)^2 var_k``.
    """
    n = len(inputs.sources)
    if inputs.matrix is None:
        return np.full((3, n), np.nan)
    jac = error_jacobian(inputs.error_model.robot, q, inputs.error_model)[:3]
    contrib = (jac @ inputs.matrix) ** 2 * np.array([s.variance for s in inputs.sources])
    total = contrib.sum(axis=1, keepdims=True)
    return np.where(total > 0, contrib / np.where(total > 0, total, 1.0), np.nan)


def sobol_indices(sampler, q: np.ndarray, n_base: int = 1024, seed: int = 0,
                  outputs: Sequence[str] = OUTPUTS, num_resamples: int = 100,
                  conf_level: float = 0.95, chunk: int = 100_000,
                  progress: Callable[[int], None] | None = None) -> SobolIndices:
    """First-order and total Sobol indices of every random input, via SALib.

    Parameters
    ----------
    sampler : ErrorBudget or ClearanceModel
        Its independent inputs (see :func:`random_inputs`) are the Sobol factors.
    q : ndarray of shape (n_joints,)
        Joint values [rad, m].
    n_base : int
        SALib's base sample size N, a power of two (Sobol sequences balance only then);
        the kinematics runs N (n_inputs + 2) times.
    seed : int
        Seeds SALib's scrambled Sobol sequence and its bootstrap.
    outputs : names from :data:`OUTPUTS`
    num_resamples, conf_level : bootstrap settings of the confidence intervals.
    chunk : model evaluations per batch (bounds the memory).
    progress : callable, optional, called with the number of evaluations done per batch.
    """
    from SALib.analyze import sobol as sobol_analyze
    from SALib.sample import sobol as sobol_sample

    if n_base < 2 or n_base & (n_base - 1):
        raise InputError(f"Sobol base sample size {n_base}: must be a power of two >= 2 (e.g. 1024)")
    unknown = [o for o in outputs if o not in OUTPUTS]
    if unknown:
        raise InputError(f"unknown Sobol output(s) {', '.join(unknown)} (known: {', '.join(OUTPUTS)})")
    inputs = random_inputs(sampler)
    d = len(inputs.sources)
    if d == 0:
        raise InputError("Sobol indices: the error budget has no sources")
    problem = {"num_vars": d, "names": [f"x{k}" for k in range(d)], "bounds": [[0.0, 1.0]] * d}
    u = sobol_sample.sample(problem, n_base, calc_second_order=False, seed=seed)
    bootstrap_seed = int(np.random.SeedSequence([seed, 1]).generate_state(1)[0]) | 1
    robot, em = inputs.error_model.robot, inputs.error_model
    nominal = tcp_poses(robot, q)
    cols = [OUTPUTS.index(o) for o in outputs]
    y = np.empty((u.shape[0], len(cols)))
    for start in range(0, u.shape[0], chunk):
        x = inputs.to_parameters(inputs.values_from_unit(u[start:start + chunk]))
        y[start:start + chunk] = _error_columns(robot, q, x, em, nominal)[:, cols]
        if progress is not None:
            progress(min(chunk, u.shape[0] - start))
    shape = (len(cols), d)
    s1, s1c, st, stc = (np.full(shape, np.nan) for _ in range(4))
    variance = y.var(axis=0)
    for k in range(len(cols)):
        # an output the inputs cannot move (e.g. an angle under pure translations): no indices
        if variance[k] <= 1e-24 * max(1e-300, float(np.mean(y[:, k] ** 2))):
            continue
        # SALib reads ``if seed:``, so seed 0 would give unseeded bootstrap intervals: pass
        # a never-zero seed derived from ours (odd), so that every seed repeats exactly
        res = sobol_analyze.analyze(problem, y[:, k], calc_second_order=False, num_resamples=num_resamples,
                                    conf_level=conf_level, seed=bootstrap_seed)
        s1[k], s1c[k], st[k], stc[k] = res["S1"], res["S1_conf"], res["ST"], res["ST_conf"]
    return SobolIndices(
        source_names=inputs.names, groups=inputs.groups, outputs=tuple(outputs),
        first_order=s1, first_order_conf=s1c, total_order=st, total_order_conf=stc, variance=variance,
        linear_share=linear_variance_shares(inputs, q), n_base=n_base, conf_level=conf_level,
    )


# ---------------------------------------------------------------------------------------
# Tolerance allocation
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ScaledSpread:
    """One input's standard deviation before and after allocation [its unit]."""

    name: str
    group: str
    unit: str
    nominal_std: float
    allowed_std: float


@dataclass(frozen=True)
class ToleranceAllocation:
    """The largest spread factor that keeps ``P(|dP| < tolerance) >= probability``.

    Attributes
    ----------
    factor : float
        Multiplier of the spreads of the scaled inputs (> 1: the budget may loosen).
    scaled_groups : tuple of str or None
        Groups whose spreads were scaled (None: all).
    tolerance : float
        T [m].
    probability : float
        Target p.
    nominal_probability : float
        P(|dP| < T) of the unscaled sampler, same draws.
    achieved_probability : float
        P(|dP| <= T) at ``factor``, same draws.
    spreads : list of ScaledSpread
        Every scaled input, nominal and allowed standard deviation.
    sampler : ErrorBudget or ClearanceModel with the allowed spreads
    n_samples : int
    """

    factor: float
    scaled_groups: tuple[str, ...] | None
    tolerance: float
    probability: float
    nominal_probability: float
    achieved_probability: float
    spreads: list[ScaledSpread]
    sampler: object
    n_samples: int


class _CommonRandomNumbers:
    """|dP| with the scaled inputs multiplied by s, always from the same draws."""

    def __init__(self, inputs: RandomInputs, q: np.ndarray, n_samples: int, rng: np.random.Generator,
                 scaled: np.ndarray):
        self.inputs, self.q = inputs, q
        self.robot, self.em = inputs.error_model.robot, inputs.error_model
        self.nominal = tcp_poses(self.robot, q)
        self.values = inputs.values_from_unit(rng.uniform(size=(n_samples, len(inputs.sources))))
        self.scaled = scaled
        if inputs.matrix is not None:  # linear: x(s) = s x_scaled + x_fixed
            a = inputs.matrix
            self.x_scaled = self.values[:, scaled] @ a[:, scaled].T
            self.x_fixed = self.values[:, ~scaled] @ a[:, ~scaled].T

    def norms(self, s: float) -> np.ndarray:
        if self.inputs.matrix is not None:
            x = s * self.x_scaled + self.x_fixed
        else:
            values = self.values.copy()
            values[:, self.scaled] *= s
            x = self.inputs.to_parameters(values)
        return pose_error(self.nominal, tcp_poses(self.robot, self.q, x, self.em)).position_norm


def allocate_tolerance(sampler, q: np.ndarray, tolerance: float, probability: float,
                       groups: Sequence[str] | None = None, n_samples: int = 50_000,
                       rng: np.random.Generator | None = None,
                       progress: Callable[[int], None] | None = None) -> ToleranceAllocation:
    """Largest factor on the spreads such that ``P(|dP| < tolerance) >= probability``.

    The probability is estimated on ``n_samples`` fixed draws (common random numbers):
    the factor s multiplies the values of the scaled inputs (scaling a spread and
    mean multiplies the value drawn at the same probability), so the Monte Carlo is a
    deterministic function of s. With k = ceil(p n), P >= p holds while the k-th
    smallest |dP| stays below T. That order statistic is continuous in s and, where
    the TCP error grows with the errors (every practical case; exactly so in the
    linear regime), increasing, so scipy's brentq finds where it equals T.

    Parameters
    ----------
    sampler : ErrorBudget or ClearanceModel
    q : ndarray of shape (n_joints,) [rad, m]
    tolerance : float
        T [m], > 0.
    probability : float
        Target p in (0, 1).
    groups : sequence of str, optional
        Scale only the inputs of these groups (e.g. ``["drive"]``); the others keep
        their spreads. Default: every input.
    n_samples : int
    rng : numpy Generator
    progress : callable, optional
        Called with 1 after each Monte Carlo evaluation (about 15 to 30 in all).
    """
    from scipy.optimize import brentq

    if not (tolerance > 0 and math.isfinite(tolerance)):
        raise InputError(f"tolerance {tolerance}: must be a finite number > 0")
    if not (0.0 < probability < 1.0):
        raise InputError(f"target probability {probability}: must lie strictly between 0 and 1")
    if n_samples < 10:
        raise InputError(f"tolerance allocation needs at least 10 samples, got {n_samples}")
    inputs = random_inputs(sampler)
    known = sorted({g for g, ok in zip(inputs.groups, inputs.scalable) if ok})
    group_set = None
    if groups is not None:
        group_set = set(groups)
        unknown = sorted(group_set - set(known))
        if unknown:
            raise InputError(f"unknown group(s) {', '.join(unknown)} (groups of this budget: {', '.join(known)})")
    scaled = inputs.scalable & np.array([group_set is None or g in group_set for g in inputs.groups])
    rng = rng if rng is not None else np.random.default_rng(0)
    crn = _CommonRandomNumbers(inputs, q, n_samples, rng, scaled)
    k = math.ceil(probability * n_samples)

    def excess(s: float) -> float:
        value = float(np.partition(crn.norms(s), k - 1)[k - 1]) - tolerance
        if progress is not None:
            progress(1)
        return value

    nominal_probability = float(np.mean(crn.norms(1.0) < tolerance))
    at_zero = excess(0.0)
    what = ", ".join(sorted(group_set)) if group_set else "every group"
    if at_zero >= 0:
        raise AnalysisError(
            f"P(|dP| < {tolerance * 1e3:g} mm) >= {probability:g} cannot be met by scaling {what}: even with "
            f"those spreads at zero the {probability:g} quantile of |dP| is {(at_zero + tolerance) * 1e3:.4g} mm")
    hi = 1.0
    while excess(hi) < 0:
        hi *= 4.0
        if hi > 1e9:
            raise AnalysisError(f"scaling {what} does not move the TCP: any spread meets the target")
    lo = hi / 4.0 if hi > 1.0 else 0.0
    while lo > 0.0 and excess(lo) >= 0:
        lo = lo / 4.0 if lo > 1e-12 else 0.0
    factor = float(brentq(excess, lo, hi, xtol=1e-14, rtol=1e-10))
    for _ in range(60):  # brentq may land a hair above the crossing: step to the side that meets the target
        if excess(factor) <= 0:
            break
        factor *= 1.0 - 1e-9
    spreads = [ScaledSpread(s.name, s.group, s.unit, math.sqrt(s.variance),
                            math.sqrt(s.variance) * (factor if ok else 1.0))
               for s, ok in zip(inputs.sources, scaled) if ok]
    return ToleranceAllocation(
        factor=factor, scaled_groups=tuple(sorted(group_set)) if group_set else None,
        tolerance=float(tolerance), probability=float(probability),
        nominal_probability=nominal_probability,
        achieved_probability=float(np.mean(crn.norms(factor) <= tolerance)),
        spreads=spreads, sampler=inputs.scaled_sampler(factor, group_set), n_samples=n_samples,
    )
