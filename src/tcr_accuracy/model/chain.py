"""The batched product of exponentials behind :func:`~tcr_accuracy.model.kinematics.tcp_poses`.

The running rotation R (9 entries, row-major) and translation p (3) are kept entry by
entry ("structure of arrays"), each entry a Python float when it is the same for every
sample or a contiguous (N,) array when it is not. A factor whose entries are exactly 0 or
1 costs nothing (skipped or passed through), constants are multiplied once, and only
entries that really vary per sample cost vector operations. So at a fixed pose the
nominal joint transforms fold into constants, a pure translation error costs 3
multiply-adds per nonzero component, a drive error about a coordinate axis only touches
two columns, and no (3, 3, N) einsum is needed. The result is the exact product of
exponentials (no linearisation). Pinocchio computes one pose at a time; Monte Carlo needs
millions, which is why this part is written by hand.

Inside :meth:`ScratchArrays.active <tcr_accuracy.model.scratch.ScratchArrays.active>` the
temporaries come from the active pool instead of fresh allocations.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .errors import ErrorModel
from .robot import REVOLUTE, RobotModel
from .scratch import scratch, scratch_like


def _mul(a, b):
    if isinstance(a, float):
        if isinstance(b, float):
            return a * b
        a, b = b, a  # the array first
    elif not isinstance(b, float):
        return np.multiply(a, b, out=scratch_like(a, b))
    if b == 0.0:
        return 0.0
    if b == 1.0:
        return a
    if b == -1.0:
        return np.negative(a, out=scratch_like(a))
    return np.multiply(a, b, out=scratch_like(a))


def _add(a, b):
    if isinstance(a, float):
        if isinstance(b, float) or a == 0.0:
            return a + b if isinstance(b, float) else b
    elif isinstance(b, float) and b == 0.0:
        return a
    return np.add(a, b, out=scratch_like(a, b))


def _dot3_owned(r0, r1, r2, c0, c1, c2):
    """(r0 c0 + r1 c1 + r2 c2, owned): zero/one factors skipped, arrays summed in place
    when the sum is a fresh array (owned) rather than one of the inputs."""
    acc, owned = 0.0, False
    for a, b in ((r0, c0), (r1, c1), (r2, c2)):
        term = _mul(a, b)
        if isinstance(term, float) and term == 0.0:
            continue
        if isinstance(acc, float):
            if isinstance(term, float):
                acc = acc + term
            elif acc == 0.0:
                acc, owned = term, (term is not a and term is not b)
            else:
                acc, owned = np.add(term, acc, out=scratch_like(term)), True
        elif owned:
            acc += term
        else:
            acc, owned = np.add(acc, term, out=scratch_like(acc)), True
    return acc, owned


def _dot3(r0, r1, r2, c0, c1, c2):
    return _dot3_owned(r0, r1, r2, c0, c1, c2)[0]


def _add_to(base, addend_owned):
    """base + addend, in place in the addend when it is a fresh array."""
    addend, owned = addend_owned
    if owned and not isinstance(base, float):
        addend += base
        return addend
    return _add(base, addend)


def _chain_compose(r, p, c, t):
    """(r, p) * (c, t): r, c lists of 9 entries (row-major), p, t lists of 3."""
    new_p = p
    if not all(isinstance(v, float) and v == 0.0 for v in t):
        new_p = [_add_to(p[i], _dot3_owned(r[3 * i], r[3 * i + 1], r[3 * i + 2], t[0], t[1], t[2]))
                 for i in range(3)]
    if all(isinstance(v, float) for v in c) and c == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]:
        return r, new_p
    new_r = [_dot3(r[3 * i], r[3 * i + 1], r[3 * i + 2], c[k], c[3 + k], c[6 + k])
             for i in range(3) for k in range(3)]
    return new_r, new_p


#: Angles up to this bound [rad] take the series of :func:`_small_cos_sin` (error terms are small).
SMALL_ANGLE = 0.1

# Taylor coefficients of sin x / x and cos x in powers of x^2, highest first
_SIN_SERIES = (1.0 / 362_880.0, -1.0 / 5_040.0, 1.0 / 120.0, -1.0 / 6.0, 1.0)
_COS_SERIES = (-1.0 / 3_628_800.0, 1.0 / 40_320.0, -1.0 / 720.0, 1.0 / 24.0, -0.5, 1.0)


def _small_cos_sin(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos x and sin x of an (N,) array with every |x| <= :data:`SMALL_ANGLE`, as Horner series.

    Written by hand because numpy's float64 sin and cos call libm one element at a time
    (about 7 ns each here, the largest cost of a drive-error chain), while these ten
    multiply-adds per function run on numpy's SIMD loops in place. Up to 0.1 rad the
    first omitted terms, x^11/11! and x^12/12!, are below 1e-18: the results agree with
    libm to a few units in the last place.
    """
    x2 = np.multiply(x, x, out=scratch_like(x))
    sin = np.multiply(x2, _SIN_SERIES[0], out=scratch_like(x))
    for coefficient in _SIN_SERIES[1:]:
        sin += coefficient
        if coefficient != 1.0:
            sin *= x2
    sin *= x
    cos = np.multiply(x2, _COS_SERIES[0], out=scratch_like(x))
    for coefficient in _COS_SERIES[1:]:
        cos += coefficient
        if coefficient != 1.0:
            cos *= x2
    return cos, sin


def _cos_sin(angle):
    if isinstance(angle, float):
        return float(np.cos(angle)), float(np.sin(angle))
    if angle.size and -SMALL_ANGLE <= angle.min() and angle.max() <= SMALL_ANGLE:
        return _small_cos_sin(angle)
    return np.cos(angle, out=scratch_like(angle)), np.sin(angle, out=scratch_like(angle))


def _axis_rotation(axis: np.ndarray, angle):
    """Rot(axis, angle) as 9 entries; exact zeros/ones kept for a coordinate axis."""
    return _axis_rotation_cs(axis, *_cos_sin(angle))


def _axis_rotation_cs(axis: np.ndarray, c, s):
    """Rot(axis, angle) as 9 entries from c = cos(angle) and s = sin(angle)."""
    if isinstance(c, float) and c == 1.0 and isinstance(s, float) and s == 0.0:
        return _identity()[0]
    k = int(np.argmax(np.abs(axis)))
    if abs(abs(axis[k]) - 1.0) < 1e-15:
        if axis[k] < 0:
            s = -s
        m = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        i, j = (k + 1) % 3, (k + 2) % 3
        m[3 * i + i], m[3 * j + j] = c, c
        m[3 * i + j], m[3 * j + i] = -s if isinstance(s, float) else np.negative(s, out=scratch_like(s)), s
        return m
    # Rodrigues for a general unit axis: I + sin [a] + (1 - cos) [a]^2
    hat = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    hat_sq = hat @ hat
    one_minus_c = 1.0 - c
    return [_add(float(np.eye(3)[i, k]), _add(_mul(float(hat[i, k]), s), _mul(float(hat_sq[i, k]), one_minus_c)))
            for i in range(3) for k in range(3)]


def _se3_entries(m: pin.SE3):
    return [float(v) for v in m.rotation.reshape(-1)], [float(v) for v in m.translation]


def _twist_factor(twist: list):
    """exp6 of a twist given as 6 entries (floats or (N,) arrays) -> (9 entries, 3 entries)."""
    if all(isinstance(v, float) for v in twist):
        return _se3_entries(pin.exp6(np.array(twist)))
    if all(isinstance(v, float) and v == 0.0 for v in twist[3:]):  # pure translation
        return [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], list(twist[:3])
    rot_nonzero = [k for k in range(3) if not (isinstance(twist[3 + k], float) and twist[3 + k] == 0.0)]
    lin_zero = all(isinstance(v, float) and v == 0.0 for v in twist[:3])
    if lin_zero and len(rot_nonzero) == 1:  # rotation about one coordinate axis
        axis = np.zeros(3)
        axis[rot_nonzero[0]] = 1.0
        return _axis_rotation(axis, twist[3 + rot_nonzero[0]]), [0.0, 0.0, 0.0]
    return _exp6_entries(twist)


def _exp6_entries(twist: list):
    """Rodrigues on entries (floats or (N,) arrays), as ``pin.exp6``; zero entries cost nothing.

    R = I + a [w] + b [w]^2 and V = I + b [w] + c [w]^2 (translation V v), written out
    with [w]^2 = w w^T - |w|^2 I, and the Taylor series of a, b, c below 1e-4 rad.
    """
    v, w = twist[:3], twist[3:]
    theta_sq = _add(_add(_mul(w[0], w[0]), _mul(w[1], w[1])), _mul(w[2], w[2]))
    theta_sq = np.asarray(theta_sq, dtype=float)
    theta = np.sqrt(theta_sq)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    sin_t, cos_t = np.sin(safe), np.cos(safe)
    a = np.where(small, 1.0 - theta_sq / 6.0, sin_t / safe)
    b = np.where(small, 0.5 - theta_sq / 24.0, (1.0 - cos_t) / (safe * safe))
    c = np.where(small, 1.0 / 6.0 - theta_sq / 120.0, (safe - sin_t) / (safe * safe * safe))

    def matrix(f1, f2):
        # I + f1 [w] + f2 (w w^T - theta^2 I)
        out = []
        for i in range(3):
            for k in range(3):
                entry = _mul(f2, _mul(w[i], w[k]))
                if i == k:
                    entry = _add(entry, 1.0 - f2 * theta_sq)
                else:
                    # [w]_ik = -eps_ikl w_l
                    l_ = 3 - i - k
                    sign = 1.0 if (i, k) in ((2, 1), (0, 2), (1, 0)) else -1.0
                    entry = _add(entry, _mul(f1, _mul(sign, w[l_])))
                out.append(entry)
        return out

    rot = matrix(a, b)
    if all(isinstance(e, float) and e == 0.0 for e in v):
        return rot, [0.0, 0.0, 0.0]
    left = matrix(b, c)
    trans = [_dot3(left[3 * i], left[3 * i + 1], left[3 * i + 2], v[0], v[1], v[2]) for i in range(3)]
    return rot, trans


def _column(values, i: int):
    """Row i of a (p, M) array as a float (M == 1), 0.0 when it is all zero, else a contiguous array.

    ``values`` may also be a list of rows, each a float or an (M,) array.
    """
    row = values[i]
    if isinstance(row, float):
        return row
    if row.shape[0] == 1:
        return float(row[0])
    if row[0] == 0.0 and not row.any():  # row[0] spares a pass over a random row
        return 0.0
    return row


def _identity() -> tuple[list, list]:
    return [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0]


def _chain(robot: RobotModel, q_cols: np.ndarray, x_cols: np.ndarray | None, error_model: ErrorModel | None):
    """TCP (R entries, p entries) from joint values (n, Nq) and error vectors (p, Nx), axis 1 samples.

    The factors are multiplied left to right, but a factor whose rotation is the same for
    every sample (a placement, a constant joint rotation, a translation error, a prismatic
    motion) first joins a pending factor: constant rotations multiply as floats and
    translations add up there, and the running product takes the pending factor only when
    a rotation that varies per sample comes (a drive error, a tilt). So consecutive
    placements and translations cost one product with the running rotation, not one each.
    """
    axes = robot.motion_axes
    kinds = robot.joint_kinds
    em = error_model
    running = _identity()
    pending = _identity()

    def multiply(factor):
        nonlocal running, pending
        if all(isinstance(v, float) for v in factor[0]):
            pending = _chain_compose(*pending, *factor)
        else:
            running = _chain_compose(*_chain_compose(*running, *pending), *factor)
            pending = _identity()

    def twist_at(start, stop):
        twist = [_column(x_cols, i) for i in range(start, stop)]
        if not all(isinstance(v, float) and v == 0.0 for v in twist):
            multiply(_twist_factor(twist))

    if x_cols is not None:
        twist_at(em.base_slice.start, em.base_slice.stop)
    for j, placement in enumerate(robot.joint_placements):
        multiply(_se3_entries(placement))
        value = _column(q_cols, j)
        if x_cols is not None:
            start = em.placement_slice.start + 6 * j
            twist_at(start, start + 6)
            drive = _column(x_cols, em.drive_slice.start + j)
            if kinds[j] == REVOLUTE and isinstance(value, float) and not isinstance(drive, float):
                # Rot(a, q + dq) by the angle sum on the small dq: cos and sin of q are constants
                cos_q, sin_q = _cos_sin(value)
                cos_d, sin_d = _cos_sin(drive)
                multiply((_axis_rotation_cs(axes[j][3:], _add(_mul(cos_q, cos_d), _mul(-sin_q, sin_d)),
                                            _add(_mul(sin_q, cos_d), _mul(cos_q, sin_d))), [0.0, 0.0, 0.0]))
                continue
            value = _add(value, drive)
        multiply(_joint_motion(kinds[j], axes[j], value))
    multiply(_se3_entries(robot.tool_placement))
    if x_cols is not None:
        twist_at(em.tool_slice.start, em.tool_slice.stop)
    return _chain_compose(*running, *pending)


def _joint_motion(kind, axis6, value) -> tuple[list, list]:
    """The joint's motion by value [rad or m] as (9 rotation entries, 3 translation entries)."""
    if kind == REVOLUTE:
        return _axis_rotation(axis6[3:], value), [0.0, 0.0, 0.0]
    return _identity()[0], [_mul(float(a), value) for a in axis6[:3]]


def tcp_chain_soa(robot: RobotModel, q: np.ndarray, x_t: np.ndarray | None = None,
                  error_model: ErrorModel | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The engine in structure-of-arrays form, for callers that loop over chunks.

    Parameters
    ----------
    q : array-like of shape (n_joints,) or (n_joints, N)
        Joint values [rad, m], samples on axis 1.
    x_t : array-like of shape (n_params, N) or (n_params, 1), optional
        Error vectors, transposed (samples on axis 1; contiguous rows are fastest).
        May also be a list of n_params rows, each a float (same for every sample,
        0.0 for an unused parameter) or an (N,) array.

    Returns
    -------
    rotation : (9, N) row-major entries of the TCP rotations
    position : (3, N) TCP positions [m]

    Within :meth:`ScratchArrays.active <tcr_accuracy.model.scratch.ScratchArrays.active>`
    the temporaries and both results are arrays of that pool (the results share one
    (12, N) block).
    """
    q_cols = np.asarray(q, dtype=float)
    if q_cols.ndim == 1:
        q_cols = q_cols[:, None]
    n = q_cols.shape[1]
    if x_t is not None:
        if not isinstance(x_t, list):
            x_t = np.asarray(x_t, dtype=float)
            n = max(n, x_t.shape[1])
        else:
            n = max([n] + [v.shape[0] for v in x_t if not isinstance(v, float)])
        error_model = error_model or ErrorModel(robot)
    r, p = _chain(robot, q_cols, x_t, error_model)
    block = scratch((12, n))  # from the active scratch pool, if any
    rot, pos = (np.empty((9, n)), np.empty((3, n))) if block is None else (block[:9], block[9:])
    for i, v in enumerate(r):
        rot[i] = v
    for i, v in enumerate(p):
        pos[i] = v
    return rot, pos
