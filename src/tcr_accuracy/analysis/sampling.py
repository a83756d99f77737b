"""Task-workspace sampling in configuration space, and batched inverse kinematics.

The task workspace is a Cartesian box for the TCP position and ranges of the ZYX
Euler angles (about z, then y, then x: ``R = Rz(a) Ry(b) Rx(c)``) of its orientation.
It is sampled densely in Cartesian space, every target is turned into joint values
by damped-least-squares inverse kinematics on Pinocchio (frame Jacobian and log6
error), and a sparse set whose values are spread uniformly along every joint is
picked from the dense set (stratified per joint), so that measurement points cover
the joint space the task actually uses.

Pinocchio solves one configuration at a time; here the Jacobians come from Pinocchio
in a per-target loop and the damped least-squares steps of all targets are solved
together with numpy. The per-joint stratified pick is a greedy coverage of joint
value bins, hand-written because no library selects a subset of given points that way
(scipy.stats.qmc makes new points, it does not choose among reachable ones).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from ..exceptions import InputError
from ..model.jacobians import tcp_jacobian
from ..model.kinematics import euler_zyx, rotation_from_euler_zyx, tcp_poses
from ..model.robot import RobotModel


@dataclass(frozen=True)
class TaskWorkspace:
    """A TCP position box and ZYX Euler angle ranges in the base frame.

    position_low, position_high : (3,) box corners [m]
    euler_low, euler_high : (3,) ranges of the ZYX Euler angles (a about z, b about y,
        c about x) [rad]
    """

    position_low: np.ndarray
    position_high: np.ndarray
    euler_low: np.ndarray
    euler_high: np.ndarray

    def __post_init__(self) -> None:
        for name in ("position_low", "position_high", "euler_low", "euler_high"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise InputError(f"task workspace: {name} must be 3 finite numbers, got {value}")
            object.__setattr__(self, name, value)
        if np.any(self.position_high < self.position_low) or np.any(self.euler_high < self.euler_low):
            raise InputError("task workspace: every upper bound must be >= its lower bound")

    @classmethod
    def around(cls, robot: RobotModel, q_ref: np.ndarray, half_size_m, half_angle_rad) -> "TaskWorkspace":
        """A workspace centred on the nominal TCP pose at q_ref (n_joints,)."""
        pose = tcp_poses(robot, q_ref)
        centre = pose.position[0]
        euler = euler_zyx(pose.rotation)[0]
        half_size = np.broadcast_to(np.asarray(half_size_m, dtype=float), (3,))
        half_angle = np.broadcast_to(np.asarray(half_angle_rad, dtype=float), (3,))
        return cls(centre - half_size, centre + half_size, euler - half_angle, euler + half_angle)

    def sample(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """n uniform random poses: positions (n, 3) [m] and rotations (n, 3, 3)."""
        positions = rng.uniform(self.position_low, self.position_high, (n, 3))
        euler = rng.uniform(self.euler_low, self.euler_high, (n, 3))
        return positions, rotation_from_euler_zyx(euler)


# ---------------------------------------------------------------------------------------
# Inverse kinematics
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class IkResult:
    """Inverse kinematics of N targets.

    q : (N, n_joints) joint values [rad, m] (the last iterate where it failed)
    success : (N,) reached within tolerance and inside the joint limits
    position_error : (N,) remaining |dp| [m]
    rotation_error : (N,) remaining rotation angle [rad] (0 for position-only targets)
    iterations : (N,) iterations used
    """

    q: np.ndarray
    success: np.ndarray
    position_error: np.ndarray
    rotation_error: np.ndarray
    iterations: np.ndarray

    @property
    def n_failed(self) -> int:
        return int((~self.success).sum())


def inverse_kinematics(robot: RobotModel, positions: np.ndarray, rotations: np.ndarray | None = None,
                       q_init: np.ndarray | None = None, *, tol_position: float = 1e-7,
                       tol_rotation: float = 1e-7, max_iter: int = 200, damping: float = 1e-6,
                       max_step: float = 0.2, restarts: int = 0, orientation: str = "exact",
                       rng: np.random.Generator | None = None) -> IkResult:
    """Damped least-squares IK for many TCP targets, joint limits respected by projection.

    Parameters
    ----------
    positions : (N, 3) target TCP positions [m]
    rotations : (N, 3, 3) target orientations, or None for position-only targets
    q_init : (n_joints,) or (N, n_joints) start values [rad, m]; default the working pose
    tol_position, tol_rotation : success tolerances [m, rad]
    damping : lambda^2 of the damped pseudo-inverse ``J^T (J J^T + lambda^2 I)^-1``
    max_step : largest joint step per iteration [rad or m]
    restarts : failed targets are retried this many times from random joint values
        inside the limits (rng required)
    orientation : "exact" (position and orientation within tolerance) or "best_effort"
        (position within tolerance, orientation as close as the robot can in the
        position task's null space). Use "best_effort" for robots whose TCP pose has
        fewer than 6 independent DoF, e.g. the tool-changer: j2, j3, j5 are parallel
        and j4 slides in their plane, so its frame Jacobian has rank 5.

    Returns
    -------
    IkResult; targets that fail are flagged, never dropped or filled with NaN.

    Each iteration: Pinocchio's frame Jacobian (LOCAL_WORLD_ALIGNED) per target, the
    position error and the log3 rotation error in the base frame; the damped steps
    of all active targets are one batched numpy solve. After each step the joints
    are clipped to their limits (projection).
    """
    positions = np.atleast_2d(np.asarray(positions, dtype=float))
    n_targets = positions.shape[0]
    if positions.shape[1] != 3:
        raise InputError(f"IK targets: positions must be (N, 3), got {positions.shape}")
    full_pose = rotations is not None
    if full_pose:
        rotations = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
        if rotations.shape[0] != n_targets:
            raise InputError("IK targets: positions and rotations differ in length")
    n = robot.n_joints
    if q_init is None:
        q_init = robot.working_pose
    q = np.array(np.broadcast_to(np.asarray(q_init, dtype=float), (n_targets, n)))
    if orientation not in ("exact", "best_effort"):
        raise InputError(f"IK: orientation must be 'exact' or 'best_effort', got {orientation!r}")
    result = _dls(robot, positions, rotations, q, tol_position, tol_rotation, max_iter, damping, max_step,
                  orientation)
    lo, hi = robot.joint_bounds(np.inf)
    for _ in range(restarts):
        failed = np.flatnonzero(~result.success)
        if failed.size == 0:
            break
        if rng is None:
            raise InputError("inverse_kinematics: restarts need an rng")
        start = rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi), (failed.size, n))
        retry = _dls(robot, positions[failed], None if not full_pose else rotations[failed], start,
                     tol_position, tol_rotation, max_iter, damping, max_step, orientation)
        for name in ("q", "success", "position_error", "rotation_error", "iterations"):
            getattr(result, name)[failed] = getattr(retry, name)
    return result


def _damped_step(jac: np.ndarray, err: np.ndarray, damping: float) -> np.ndarray:
    """Batched damped least squares: J^T (J J^T + d I)^-1 e for J (K, m, n), e (K, m) -> (K, n)."""
    m = jac.shape[1]
    jjt = jac @ jac.transpose(0, 2, 1) + damping * np.eye(m)
    return np.einsum("kji,kj->ki", jac, np.linalg.solve(jjt, err[..., None])[..., 0])


def _dls(robot, positions, rotations, q, tol_p, tol_r, max_iter, damping, max_step,
         orientation) -> IkResult:
    data = robot.model.createData()
    fid = robot.tool_frame_id
    n_targets, n = q.shape
    lo, hi = robot.joint_bounds(np.inf)
    full = rotations is not None
    active = np.ones(n_targets, dtype=bool)
    pos_err = np.full(n_targets, np.inf)
    rot_err = np.zeros(n_targets)
    iterations = np.zeros(n_targets, dtype=int)
    last_step = np.full(n_targets, np.inf)
    for it in range(max_iter + 1):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        e_p = np.empty((idx.size, 3))
        e_r = np.zeros((idx.size, 3))
        jac = np.empty((idx.size, 6, n))
        for k, i in enumerate(idx):
            oMf, jac[k] = tcp_jacobian(robot, q[i], data, fid)
            e_p[k] = positions[i] - oMf.translation
            if full:
                e_r[k] = pin.log3(rotations[i] @ oMf.rotation.T)  # base-frame rotation vector
        pos_err[idx] = np.linalg.norm(e_p, axis=1)
        rot_err[idx] = np.linalg.norm(e_r, axis=1)
        reached = pos_err[idx] < tol_p
        if full and orientation == "exact":
            reached &= rot_err[idx] < tol_r
        elif full:  # best effort: position reached and the orientation no longer improves
            reached &= last_step[idx] < 1e-10
        active[idx[reached]] = False
        keep = ~reached
        if it == max_iter or not keep.any():
            break
        idx, e_p, e_r, jac = idx[keep], e_p[keep], e_r[keep], jac[keep]
        if not full:
            step = _damped_step(jac[:, :3], e_p, damping)
        elif orientation == "exact":
            step = _damped_step(jac, np.concatenate([e_p, e_r], axis=1), damping)
        else:
            # position first; orientation as well as it can in the position task's null space
            j_p, j_r = jac[:, :3], jac[:, 3:]
            step = _damped_step(j_p, e_p, damping)
            null = np.eye(n) - np.linalg.pinv(j_p, rcond=1e-10) @ j_p
            j_rn = j_r @ null
            step = step + np.einsum("kij,kj->ki", null, _damped_step(j_rn, e_r - np.einsum("kij,kj->ki", j_r, step),
                                                                       damping))
        largest = np.abs(step).max(axis=1, keepdims=True)
        step *= np.minimum(1.0, max_step / np.maximum(largest, 1e-300))
        new_q = np.clip(q[idx] + step, lo, hi)
        last_step[idx] = np.abs(new_q - q[idx]).max(axis=1)
        q[idx] = new_q
        iterations[idx] += 1
    success = pos_err < tol_p
    if full and orientation == "exact":
        success &= rot_err < tol_r
    return IkResult(q=q, success=success, position_error=pos_err, rotation_error=rot_err,
                    iterations=iterations)


# ---------------------------------------------------------------------------------------
# Stratified sparse subset
# ---------------------------------------------------------------------------------------
def stratified_subset(q_dense: np.ndarray, n: int, rng: np.random.Generator,
                      n_bins: int | None = None, swap_passes: int = 3) -> np.ndarray:
    """Indices of n rows of q_dense (N, n_joints) spread uniformly along every joint.

    Each joint's range over the dense set is cut into ``n_bins`` (default n) equal-width
    bins. Points are picked one at a time: the candidate that lands in the most joint
    bins still empty, then in the least crowded ones, ties broken at random. Swap
    passes then exchange a picked point for an unpicked one whenever that fills more
    empty bins than it empties. With a dense set covering the bins this is a
    Latin-hypercube pick among reachable configurations.

    Returns
    -------
    (n,) int indices into q_dense, without repetition.
    """
    q_dense = np.asarray(q_dense, dtype=float)
    n_dense, n_joints = q_dense.shape
    if n > n_dense:
        raise InputError(f"stratified sampling: asked for {n} points from only {n_dense} reachable ones; "
                         "sample the task workspace more densely")
    n_bins = n_bins or n
    lo, hi = q_dense.min(axis=0), q_dense.max(axis=0)
    width = np.where(hi > lo, hi - lo, 1.0)
    bins = np.clip(((q_dense - lo) / width * n_bins).astype(int), 0, n_bins - 1)  # (N, n_joints)
    counts = np.zeros((n_joints, n_bins))
    taken = np.zeros(n_dense, dtype=bool)
    chosen = np.empty(n, dtype=int)
    cols = np.arange(n_joints)
    for k in range(n):
        load = counts[cols, bins]  # (N, n_joints) picks already in each of the point's bins
        score = (load == 0).sum(axis=1) * (n + 1.0) * n_joints - load.sum(axis=1)
        score[taken] = -np.inf
        best = np.flatnonzero(score == score.max())
        pick = best[rng.integers(best.size)]
        chosen[k] = pick
        taken[pick] = True
        counts[cols, bins[pick]] += 1
    for _ in range(swap_passes):
        swapped = False
        for k in rng.permutation(n):
            out = chosen[k]
            counts[cols, bins[out]] -= 1
            loss = int((counts[cols, bins[out]] == 0).sum())  # bins that empty without it
            gain = (counts[cols, bins] == 0).sum(axis=1)
            gain[taken] = -1
            cand = int(np.argmax(gain))
            if gain[cand] > loss:
                taken[out], taken[cand] = False, True
                chosen[k] = cand
                swapped = True
            counts[cols, bins[chosen[k]]] += 1
        if not swapped:
            break
    return chosen


@dataclass(frozen=True)
class WorkspaceSample:
    """Result of :func:`sample_task_workspace`.

    q : (n, n_joints) sparse, per-joint uniform sample [rad, m]
    dense_q : (N_ok, n_joints) all dense targets the IK reached
    n_dense : dense targets tried
    n_failed : dense targets the IK did not reach (within tolerance and limits)
    """

    q: np.ndarray
    dense_q: np.ndarray
    n_dense: int
    n_failed: int


def sample_task_workspace(robot: RobotModel, workspace: TaskWorkspace, n: int, rng: np.random.Generator,
                          *, n_dense: int = 2000, q_init: np.ndarray | None = None,
                          **ik_options) -> WorkspaceSample:
    """The seed's sampling: dense Cartesian sampling, IK, per-joint stratified pick of n."""
    positions, rotations = workspace.sample(n_dense, rng)
    ik = inverse_kinematics(robot, positions, rotations, q_init, rng=rng, **ik_options)
    dense_q = ik.q[ik.success]
    if dense_q.shape[0] < n:
        raise InputError(f"task workspace: the IK reached only {dense_q.shape[0]} of {n_dense} dense "
                         f"targets, fewer than the {n} points asked for; check the box and angle ranges "
                         "against the robot's reach")
    pick = stratified_subset(dense_q, n, rng)
    return WorkspaceSample(q=dense_q[pick], dense_q=dense_q, n_dense=n_dense, n_failed=ik.n_failed)
