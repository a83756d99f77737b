"""TCP error along a joint trajectory: Monte Carlo bands of x, y, z over time.

Each Monte Carlo sample is one as-built robot (one draw of the error budget), and it
follows the whole motion: the errors stay fixed while the joints move, as the link
and drive errors of one physical robot do. At each time step the TCP error of every
sample gives the mean, the standard deviation and two quantiles of dx, dy, dz; the
first-order (Jacobian) standard deviation is computed next to them as a check.

Trajectories come from a CSV file (:func:`read_trajectory_csv`) or from the built-in
tool-change motion of the tool-changer (:func:`tool_change_motion`).
"""

from __future__ import annotations

import csv
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..model.errors import ErrorBudget
from ..exceptions import InputError
from ..model.jacobians import error_jacobian
from ..model.kinematics import tcp_poses
from ..model.robot import JointLimitWarning, RobotModel
from ..units import JOINT_COLUMN_UNITS, PRISMATIC, parse_number

#: Joint column suffixes and their factor to SI, per joint kind.
UNIT_SUFFIXES = JOINT_COLUMN_UNITS
TIME_COLUMN = "t_s"


@dataclass(frozen=True)
class JointTrajectory:
    """Joint values over time.

    time : ndarray of shape (T,) [s], strictly increasing
    q : ndarray of shape (T, n_joints) [rad, m]
    source : str, where it came from (file name or ``built-in tool change``)
    """

    time: np.ndarray
    q: np.ndarray
    source: str

    def __len__(self) -> int:
        return self.time.shape[0]


# ---------------------------------------------------------------------------------------
# Reading a trajectory file
# ---------------------------------------------------------------------------------------
def _column_map(robot: RobotModel, header: list[str], path: str) -> tuple[list[tuple[int, float]], int | None]:
    """For each joint, (column index, factor to SI); and the time column index."""
    names = [h.strip() for h in header]
    expected = []
    for name, kind in zip(robot.joint_names, robot.joint_kinds):
        expected.append(" or ".join(f"{name}_{u}" for u in UNIT_SUFFIXES[kind]))
    hint = f"expected one column per joint ({'; '.join(expected)}) and optionally {TIME_COLUMN}"
    seen: dict[str, int] = {}
    for c, h in enumerate(names):
        if h in seen:
            raise InputError(f"{path}: row 1, column {c + 1}: column {h!r} appears twice")
        seen[h] = c
    joints = []
    used = set()
    for name, kind in zip(robot.joint_names, robot.joint_kinds):
        found = [(seen[f"{name}_{u}"], f) for u, f in UNIT_SUFFIXES[kind] .items() if f"{name}_{u}" in seen]
        if not found:
            wrong = [h for h in names if h.startswith(f"{name}_")]
            why = f" ({wrong[0]!r} has the wrong unit for a {kind} joint)" if wrong else ""
            raise InputError(f"{path}: row 1: no column for joint {name}{why}; {hint}")
        if len(found) > 1:
            raise InputError(f"{path}: row 1: joint {name} has more than one column; {hint}")
        joints.append(found[0])
        used.add(found[0][0])
    time_col = seen.get(TIME_COLUMN)
    if time_col is not None:
        used.add(time_col)
    for c, h in enumerate(names):
        if c not in used:
            raise InputError(f"{path}: row 1, column {c + 1}: unknown column {h!r}; {hint}")
    return joints, time_col


def read_trajectory_csv(path: str | Path, robot: RobotModel) -> JointTrajectory:
    """Read a joint trajectory from a CSV file.

    One row per time step; one column per joint of the robot named ``<joint>_deg`` or
    ``<joint>_rad`` (revolute) or ``<joint>_mm`` or ``<joint>_m`` (prismatic), in any
    order; an optional ``t_s`` column with strictly increasing times [s] (without it
    the rows are 1 s apart). Every problem raises :class:`InputError` naming the file,
    the row (1 = header) and the column; values outside the joint limits warn once.

    Returns
    -------
    JointTrajectory with q of shape (T, n_joints) [rad, m].
    """
    path = Path(path)
    from ..input_files import SIZE_LIMITS, read_input_text

    text = read_input_text(path, "trajectory file", limit=SIZE_LIMITS["table"])
    try:
        rows = [r for r in csv.reader(text.splitlines())]
    except csv.Error as exc:  # a cell over the csv module's field limit
        raise InputError(f"{path}: not delimited text the reader takes ({exc})") from None
    numbered = [(i + 1, r) for i, r in enumerate(rows) if any(cell.strip() for cell in r)]
    if not numbered:
        raise InputError(f"{path}: the trajectory file is empty")
    (_, header), body = numbered[0], numbered[1:]
    joints, time_col = _column_map(robot, header, str(path))
    if not body:
        raise InputError(f"{path}: no data rows after the header")
    q = np.empty((len(body), robot.n_joints))
    time = np.empty(len(body))
    for i, (line, row) in enumerate(body):
        if len(row) != len(header):
            raise InputError(f"{path}: row {line}: {len(row)} values, the header has {len(header)} columns")
        for j, (col, factor) in enumerate(joints):
            q[i, j] = _number(row[col], path, line, header[col]) * factor
        time[i] = _number(row[time_col], path, line, header[time_col]) if time_col is not None else float(i)
    if time_col is not None:
        steps = np.diff(time)
        if (steps <= 0).any():
            i = int(np.argmax(steps <= 0)) + 1
            raise InputError(f"{path}: row {body[i][0]}, column {TIME_COLUMN!r}: times must increase "
                             f"strictly ({time[i - 1]:g} then {time[i]:g})")
    _warn_limits(robot, q, str(path), [line for line, _ in body])
    return JointTrajectory(time=time, q=q, source=str(path))


def _number(cell: str, path: Path, line: int, column: str) -> float:
    try:
        value = parse_number(cell, finite=False)  # strict: 1_5 and full-width digits are no numbers
    except ValueError:
        raise InputError(f"{path}: row {line}, column {column.strip()!r}: {cell.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{path}: row {line}, column {column.strip()!r}: {cell.strip()!r} is not a finite number")
    return value


def _warn_limits(robot: RobotModel, q: np.ndarray, source: str, lines: list[int]) -> None:
    lo, hi = robot.lower_limits, robot.upper_limits
    outside = (q < lo) | (q > hi)  # NaN limits compare False: unbounded
    if outside.any():
        i, j = (int(v) for v in np.argwhere(outside)[0])
        scale, unit = robot.display_scale[j], robot.display_units[j]
        warnings.warn(f"{source}: row {lines[i]}: joint {robot.joint_names[j]} = {q[i, j] * scale:.6g} {unit} "
                      f"is outside its limits [{lo[j] * scale:.6g}, {hi[j] * scale:.6g}] {unit} "
                      f"({int(outside.any(axis=1).sum())} rows outside)", JointLimitWarning, stacklevel=3)


# ---------------------------------------------------------------------------------------
# The built-in tool-change motion
# ---------------------------------------------------------------------------------------
#: Stowed pose of the tool-changer: turret straight, arm raised and folded, telescope in.
STOWED_POSE = np.array([0.0, math.radians(60.0), math.radians(-80.0), 0.0, math.radians(0.0), 0.0])


def quintic_time_scaling(tau: np.ndarray) -> np.ndarray:
    """s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 on [0, 1]: zero speed and acceleration at both ends."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def tool_change_motion(robot: RobotModel, n_steps: int = 121, approach_s: float = 8.0,
                       extend_s: float = 4.0, extension: float = 0.2,
                       stowed: np.ndarray | None = None) -> JointTrajectory:
    """The tool-changer's motion to a cutter: approach, then extend the telescopic arm.

    Phase 1 (``approach_s`` seconds): every joint moves from the stowed pose to the
    seed's working pose (telescope retracted) with quintic time scaling. Phase 2
    (``extend_s`` seconds): the telescopic arm (the prismatic joint) extends by
    ``extension`` metres to push the quick-change connector onto the cutter holder.

    Returns
    -------
    JointTrajectory with ``n_steps`` samples evenly spaced in time.
    """
    kinds = robot.joint_kinds
    if kinds.count(PRISMATIC) != 1 or len(kinds) != 6:
        raise InputError(f"the built-in tool-change motion is for the tool-changer (5R + 1P); robot "
                         f"{robot.name} has other joints: give its trajectory", parameter="robot",
                         value=robot.name)
    if n_steps < 2:
        raise InputError(f"n_steps={n_steps}: need at least 2", parameter="n_steps", value=n_steps)
    start = STOWED_POSE if stowed is None else np.asarray(stowed, dtype=float)
    goal = robot.working_pose
    telescope = kinds.index(PRISMATIC)
    time = np.linspace(0.0, approach_s + extend_s, n_steps)
    s1 = quintic_time_scaling(time / approach_s)[:, None]
    q = start + s1 * (goal - start)
    s2 = quintic_time_scaling((time - approach_s) / extend_s)
    q[:, telescope] = np.where(time > approach_s, goal[telescope] + s2 * extension, q[:, telescope])
    _warn_limits(robot, q, "built-in tool change", list(range(1, n_steps + 1)))
    return JointTrajectory(time=time, q=q, source="built-in tool change")


# ---------------------------------------------------------------------------------------
# Monte Carlo error bands
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrajectoryErrorBands:
    """Statistics of the TCP position error at every time step.

    Attributes
    ----------
    trajectory : JointTrajectory (T steps)
    nominal_position : ndarray of shape (T, 3) [m]
    mean, std : ndarray of shape (T, 3)
        Mean and standard deviation of dx, dy, dz [m].
    lower, upper : ndarray of shape (T, 3)
        The ``quantiles`` of dx, dy, dz [m].
    quantiles : (float, float)
    norm_mean, norm_upper : ndarray of shape (T,)
        Mean and upper quantile of |dP| [m].
    first_order_std : ndarray of shape (T, 3)
        Standard deviation predicted by the error Jacobian [m].
    n_samples : int
    source_names : list of str, length n_sources
        The sources of an error budget (empty for other samplers).
    contributions : ndarray of shape (T, n_sources, 3)
        First-order standard deviation of dx, dy, dz caused by each source alone,
        ``|J a_k| std_k`` [m]: which error dominates which axis when (seed Fig. 18).
        Shape (T, 0, 3) for samplers that are not linear error budgets.
    """

    trajectory: JointTrajectory
    nominal_position: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    quantiles: tuple[float, float]
    norm_mean: np.ndarray
    norm_upper: np.ndarray
    first_order_std: np.ndarray
    n_samples: int
    source_names: list[str] = field(default_factory=list)
    contributions: np.ndarray | None = None


def trajectory_error_bands(budget: ErrorBudget, trajectory: JointTrajectory, n_samples: int,
                           rng: np.random.Generator, quantiles: tuple[float, float] = (0.025, 0.975),
                           chunk: int = 100_000, progress: Callable[[int], None] | None = None
                           ) -> TrajectoryErrorBands:
    """Monte Carlo bands of the TCP position error along a trajectory.

    Parameters
    ----------
    budget : ErrorBudget
    trajectory : JointTrajectory with q of shape (T, n_joints)
    n_samples : int
        As-built robots, each drawn once and followed along the whole trajectory.
    rng : numpy Generator
    quantiles : (low, high) probabilities of the band
    chunk : rows (time steps x samples) evaluated at once; bounds the memory
    progress : callable, optional
        Called with the number of time steps finished after each block.
    """
    if n_samples < 2:
        raise InputError(f"trajectory Monte Carlo needs at least 2 samples, got {n_samples}")
    lo_q, hi_q = quantiles
    if not 0.0 <= lo_q < hi_q <= 1.0:
        raise InputError(f"band quantiles {quantiles}: need 0 <= low < high <= 1")
    robot, em = budget.error_model.robot, budget.error_model
    q = trajectory.q
    n_steps = q.shape[0]
    x = budget.sample(n_samples, rng)  # (n, p): one as-built robot per sample
    nominal = tcp_poses(robot, q).position  # (T, 3)
    block = max(1, chunk // n_samples)
    mean, std, lower, upper = (np.empty((n_steps, 3)) for _ in range(4))
    norm_mean, norm_upper = np.empty(n_steps), np.empty(n_steps)
    for start in range(0, n_steps, block):
        qb = q[start:start + block]
        b = qb.shape[0]
        pos = tcp_poses(robot, np.repeat(qb, n_samples, axis=0), np.tile(x, (b, 1)), em).position
        err = pos.reshape(b, n_samples, 3) - nominal[start:start + b, None, :]
        sl = slice(start, start + b)
        mean[sl] = err.mean(axis=1)
        std[sl] = err.std(axis=1, ddof=1)
        lower[sl], upper[sl] = np.quantile(err, [lo_q, hi_q], axis=1)
        norm = np.linalg.norm(err, axis=2)
        norm_mean[sl] = norm.mean(axis=1)
        norm_upper[sl] = np.quantile(norm, hi_q, axis=1)
        if progress is not None:
            progress(b)
    cov = budget.parameter_covariance()
    linear = isinstance(budget, ErrorBudget)
    if linear:
        per_source_std = np.sqrt([s.variance for s in budget.sources])
        matrix = budget.matrix
    first_order = np.empty((n_steps, 3))
    contributions = np.zeros((n_steps, len(budget.sources) if linear else 0, 3))
    with warnings.catch_warnings():  # limits were reported once when the trajectory was made
        warnings.simplefilter("ignore", JointLimitWarning)
        for t in range(n_steps):
            jac = error_jacobian(robot, q[t], em)[:3]
            first_order[t] = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jac, cov, jac), 0.0))
            if linear:
                contributions[t] = (np.abs(jac @ matrix) * per_source_std).T
    return TrajectoryErrorBands(
        trajectory=trajectory, nominal_position=nominal, mean=mean, std=std, lower=lower, upper=upper,
        quantiles=(float(lo_q), float(hi_q)), norm_mean=norm_mean, norm_upper=norm_upper,
        first_order_std=first_order, n_samples=n_samples,
        source_names=budget.source_names if linear else [], contributions=contributions,
    )
