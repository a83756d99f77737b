"""``angle_table``: each joint's error as a smooth table of its absolute angle (a cubic spline over
the travel the data cover), for errors that are not periodic in one revolution."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..units import REVOLUTE
from .joint_columns import JointColumnsEffect
from .fit_policy import FitPolicy

#: Spline degree (cubic: a continuous curvature, what the roughness penalty measures)
DEGREE = 3
#: The functions the table must not contain (another effect's): joint_offsets (1), encoder_scale (q),
#: transmission's first and second harmonics
CONSTRAINED = 6
#: Gauss-Legendre points per knot interval the constraint and the penalty are integrated on
GAUSS_POINTS = 8
#: A mode oscillating this many times per revolution or more reads as a cyclic gear or encoder error (cyclic's
#: first order is 3; transmission holds 1 and 2), a slower one as a smooth error over the travel
CYCLIC_PER_TURN = 2.5
#: Narrowest travel a table spans [rad] (a joint the data barely move still gets a well-posed table)
MIN_SPAN = 0.2
#: Poses per parameter over the revolute joints the diagnosis asks of the data (each pose's three
#: coordinates fall on every joint's table at once; the roughness penalty holds what they leave free)
POSES_PER_PARAMETER = 8
#: Knot intervals per joint at most (a table of 253 modes a joint: hundreds at 10^4 poses)
MAX_INTERVALS = 256
#: The share of each knot's place set by the spacing of equal intervals, the rest by the data's
#: density: every interval keeps at least this share of an equal one, where the poses are sparse too
UNIFORM_SHARE = 0.2


@dataclass(frozen=True)
class AngleTableFitPolicy(FitPolicy):
    """The tables span the travel the data cover, with as many knots as the poses support, under
    a roughness penalty."""

    def options_for_data(self, robot, q, context) -> dict:
        """Each joint's measured travel (``lower``, ``upper`` [rad]), the knot intervals and where the
        knots sit (``knots``): :data:`POSES_PER_PARAMETER` poses per parameter over the revolute
        joints, 8 to :data:`MAX_INTERVALS` intervals (5 to 253 parameters per joint: hundreds at 10^4
        poses, each fit taking the table's columns from the fold Gram matrices), and the knots of
        each joint at the quantiles of its measured angles (:func:`density_knots`): more where the
        poses are dense."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        revolute = sum(k == REVOLUTE for k in robot.joint_kinds)
        intervals = int(min(MAX_INTERVALS, max(8, CONSTRAINED - DEGREE
                                               + len(q) // (POSES_PER_PARAMETER * max(revolute, 1)))))
        lower, upper = q.min(axis=0), q.max(axis=0)
        knots = [[float(v) for v in density_knots(q[:, j], lower[j], upper[j], intervals)]
                 if kind == REVOLUTE else None for j, kind in enumerate(robot.joint_kinds)]
        return {"intervals": intervals, "lower": [float(v) for v in lower], "upper": [float(v) for v in upper],
                "knots": knots}

    def penalty_weights(self, effect) -> np.ndarray:
        """(k,) roughness weight of each parameter: the mean squared curvature of its mode (unit
        RMS) over 81, the curvature of cyclic's lowest order (sin 3q at unit RMS), so that one
        lambda penalises both effects' curvature alike: the fit's penalty is
        lambda * sum(w * (theta / scale)^2)."""
        return np.concatenate([effect.table(j).weights for j in effect.revolute])


@dataclass(frozen=True)
class JointTable:
    """One joint's table: knots, the map from parameters to B-spline coefficients, and each
    parameter's roughness weight.

    Attributes
    ----------
    knots : (intervals + 2 * DEGREE + 1,) [rad], clamped at the travel's ends
    modes : (intervals + DEGREE, m) B-spline coefficients of each parameter's function [rad/rad]
    weights : (m,) mean squared curvature of each mode over 81 [1]
    """

    knots: np.ndarray
    modes: np.ndarray
    weights: np.ndarray

    def values(self, angles: np.ndarray) -> np.ndarray:
        """(M, m) each mode's value at angles (M,) [rad]; outside the travel, its value at the nearer end."""
        from scipy.interpolate import BSpline

        x = np.clip(np.asarray(angles, dtype=float), self.knots[0], self.knots[-1])
        return np.asarray(BSpline.design_matrix(x, self.knots, DEGREE) @ self.modes)


def travel(lower: float, upper: float) -> tuple[float, float]:
    """A joint's table span [rad]: its travel, widened about the middle to :data:`MIN_SPAN`."""
    lower, upper = float(lower), float(upper)
    if upper - lower < MIN_SPAN:
        middle = 0.5 * (lower + upper)
        lower, upper = middle - MIN_SPAN / 2, middle + MIN_SPAN / 2
    return lower, upper


def density_knots(angles: np.ndarray, lower: float, upper: float, intervals: int) -> np.ndarray:
    """(intervals - 1,) the inner knots of one joint's table [rad]: the quantiles of its measured
    angles (each interval holding as many poses), moved a share :data:`UNIFORM_SHARE` of the way to
    the equal intervals' knots, so that every interval keeps at least that share of an equal one
    (no interval collapses where the poses pile up, and sparse stretches still get knots)."""
    lower, upper = travel(lower, upper)
    share = np.linspace(0.0, 1.0, intervals + 1)[1:-1]
    angles = np.clip(np.asarray(angles, dtype=float), lower, upper)
    quantile = np.quantile(angles, share) if angles.size else lower + share * (upper - lower)
    return (1.0 - UNIFORM_SHARE) * quantile + UNIFORM_SHARE * (lower + share * (upper - lower))


def joint_table(lower: float, upper: float, intervals: int, inner=None) -> JointTable:
    """The table of one joint over [lower, upper] [rad] with ``intervals`` knot intervals, equal or
    with the inner knots ``inner`` (intervals - 1,) [rad] (:func:`density_knots`).

    The B-spline coefficients are restricted to the functions orthogonal (over the travel) to
    1, q, sin q, cos q, sin 2q, cos 2q -- joint_offsets', encoder_scale's and transmission's --
    and, within that space, to the eigenvectors of the roughness (mean squared second derivative)
    relative to the mean square (Demmler-Reinsch): each parameter is one mode of unit RMS and
    its penalty is one number, so the fit's diagonal penalty is the exact roughness penalty.
    The modes are fixed by (lower, upper, intervals, inner) alone, each with its first coefficient
    positive (from the lower end), so a file's options rebuild the same table.
    """
    from scipy.interpolate import BSpline
    from scipy.linalg import eigh

    lower, upper = travel(lower, upper)
    inner = np.linspace(lower, upper, intervals + 1) if inner is None else \
        np.concatenate([[lower], np.clip(np.asarray(inner, dtype=float), lower, upper), [upper]])
    knots = np.concatenate([np.full(DEGREE, lower), inner, np.full(DEGREE, upper)])
    # Gauss-Legendre points in every knot interval: the integrals over the travel below are exact for the
    # splines' piecewise polynomials (and within rounding for the harmonics)
    nodes, weights = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    half = np.diff(inner)[:, None] / 2
    grid = ((inner[:-1, None] + inner[1:, None]) / 2 + half * nodes).ravel()
    root = np.sqrt((half * weights).ravel() / (upper - lower))  # square roots of the weights of a mean
    basis = BSpline.design_matrix(grid, knots, DEGREE).toarray()  # (G, nb)
    forbidden = np.stack([np.ones_like(grid), grid, np.sin(grid), np.cos(grid), np.sin(2 * grid),
                          np.cos(2 * grid)], axis=1)
    span = np.linalg.svd(root[:, None] * forbidden, full_matrices=False)[0]  # (G, 6) orthonormal in the mean
    # coefficient vectors whose function has no component along those six: the null space of (6, nb)
    null = np.linalg.svd(span.T @ (root[:, None] * basis))[2][CONSTRAINED:].T  # (nb, nb - 6)
    curvature = root[:, None] * BSpline(knots, null, DEGREE).derivative(2)(grid)  # (G, nb - 6)
    roughness = curvature.T @ curvature
    values = root[:, None] * (basis @ null)
    mass = values.T @ values
    eigenvalues, vectors = eigh(roughness, mass)  # vectors^T mass vectors = 1: unit-RMS modes
    modes = null @ vectors
    # each mode's sign: its first coefficient from the lower end that is not negligible is positive (its
    # largest would tie between the two ends of a symmetric mode, and a rounding would flip it)
    first = np.argmax(np.abs(modes) > 1e-3 * np.abs(modes).max(axis=0), axis=0)
    modes = modes * np.sign(modes[first, np.arange(modes.shape[1])])
    return JointTable(knots, modes, np.maximum(eigenvalues, 0.0) / 81.0)


class AngleTable(JointColumnsEffect):
    """Each revolute joint's angle error as a smooth table of its absolute angle: a cubic B-spline
    over the travel the data cover (not periodic), ``dq_j = sum_i theta_ji f_ji(q_j)``.

    The physics: a UR joint turns +-360 deg, and some of its errors follow the absolute angle
    rather than the angle modulo one turn: the cables and hoses through the joint wind up and
    pull harder the further it turns, a multi-turn encoder (or the gear train behind a
    single-turn one) repeats its nonlinearity over several turns, not one. Such an error at q and
    q + 2 pi differs, which no Fourier series of q (``transmission``, ``cyclic``) can hold.

    The table holds only what the other joint-side effects cannot: each mode ``f_ji`` is
    orthogonal, over the travel, to 1 (``joint_offsets``), q (``encoder_scale``) and the first
    and second harmonics (``transmission``), and the modes diagonalise the roughness penalty
    (mean squared curvature; :func:`joint_table`), so the fit's penalty ``lambda * sum w theta^2``
    is the curvature penalty and lambda is chosen by held-out error as for ``cyclic``. Outside
    the travel a table holds its value at the nearer end. Parameters ``angle_table.<joint>.m<i>``
    [rad], the RMS of mode i over the travel, smoothest first. Options: ``intervals`` (knot
    intervals per joint, ``intervals - 3`` parameters), ``lower``, ``upper`` (each joint's travel
    [rad]; default its limits, +-pi when it has none), ``knots`` (per joint, its ``intervals - 1``
    inner knots [rad], or None: equal intervals): the diagnosis sets them from the data (knots
    where the poses are dense) and keeps them for any prediction.
    """

    name = "angle_table"
    in_words = "errors that follow each joint's absolute angle"
    summary = ("joint errors as smooth tables of each joint's absolute angle (gear and encoder errors beyond the "
               "Fourier series' orders, cable wind-up, multi-turn encoders)")
    physics = ("gear, encoder and cable errors over a joint's travel are a few hundred microradians; a mode "
               "above 1 mrad (3.4 arc-min) is a joint slipping or a cable snagging, not a smooth table")
    family = "periodic"
    # after cyclic: where a Fourier series and a table explain the data alike, the periodic gear error is the
    # more basic cause
    fit_policy = AngleTableFitPolicy(order=66.0, last_resort=True)

    def __init__(self, robot, *, intervals: int = 16, lower: list | None = None, upper: list | None = None,
                 knots: list | None = None) -> None:
        super().__init__(robot)
        if intervals < CONSTRAINED - DEGREE + 1:
            raise ValueError(f"angle_table needs at least {CONSTRAINED - DEGREE + 1} knot intervals, got {intervals}")
        self.intervals = int(intervals)
        low, high = robot.joint_bounds()
        for given, name in ((lower, "lower"), (upper, "upper")):
            if given is not None and len(given) != robot.n_joints:
                raise ValueError(f"angle_table {name}: {len(given)} values for {robot.n_joints} joints")
            for k, value in enumerate(given or ()):
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise ValueError(f"angle_table {name}[{k}]: {value!r} is not a number [rad]")
        # lists, as a result file holds them
        self.lower = None if lower is None else [float(v) for v in lower]
        self.upper = None if upper is None else [float(v) for v in upper]
        self._span = (np.asarray(self.lower if lower is not None else low, dtype=float),
                      np.asarray(self.upper if upper is not None else high, dtype=float))
        inverted = [robot.joint_names[j] for j in np.flatnonzero(self._span[1] < self._span[0])]
        if inverted:
            raise ValueError(f"angle_table: travel of {', '.join(inverted)} ends below where it starts")
        if knots is not None and len(knots) != robot.n_joints:
            raise ValueError(f"angle_table knots: {len(knots)} lists for {robot.n_joints} joints")
        for j, inner in enumerate(knots or ()):
            if inner is None:
                continue
            values = np.asarray(inner, dtype=float) if all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in inner) else None
            low, high = travel(self._span[0][j], self._span[1][j])
            if values is None or values.size != self.intervals - 1 or not np.all(np.isfinite(values)) or \
                    np.any(np.diff(np.concatenate([[low], values, [high]])) <= 0):
                raise ValueError(f"angle_table knots[{j}]: {self.intervals - 1} increasing angles [rad] strictly "
                                 f"inside the travel {low:.6g} to {high:.6g} rad, one per inner knot")
        self.knots = None if knots is None else [None if k is None else [float(v) for v in k] for k in knots]

    @cached_property
    def revolute(self) -> tuple[int, ...]:
        """Indices of the revolute joints (each has a table)."""
        return tuple(j for j, kind in enumerate(self.robot.joint_kinds) if kind == REVOLUTE)

    @property
    def modes_per_joint(self) -> int:
        return self.intervals + DEGREE - CONSTRAINED

    def table(self, j: int) -> JointTable:
        """The table of joint index j (built once)."""
        tables = self.__dict__.setdefault("_tables", {})
        if j not in tables:
            inner = self.knots[j] if self.knots is not None else None
            tables[j] = joint_table(self._span[0][j], self._span[1][j], self.intervals, inner)
        return tables[j]

    def parameter_names(self):
        return [f"angle_table.{self.robot.joint_names[j]}.m{i}" for j in self.revolute
                for i in range(1, self.modes_per_joint + 1)]

    def parameter_units(self):
        return ["rad"] * self.n_params

    def parameter_scales(self):
        # 35 urad RMS per mode: cyclic's 50 urad harmonic amplitude at the same RMS, so that one penalty
        # lambda weighs both effects' curvature alike
        return np.full(self.n_params, 5e-5 / math.sqrt(2.0))

    def mode_cycles_per_turn(self) -> np.ndarray:
        """(k,) how many times each parameter's mode oscillates per revolution of its joint: half its
        sign changes over the travel, over the travel in turns [1/rev]."""
        cycles = []
        for j in self.revolute:
            table = self.table(j)
            grid = np.linspace(table.knots[0], table.knots[-1], 4001)
            values = table.values(grid)
            # sign changes of each mode, ignoring where it only grazes zero
            signs = np.sign(np.where(np.abs(values) > 1e-6 * np.abs(values).max(axis=0), values, 0.0))
            changes = np.array([np.count_nonzero(np.diff(col[col != 0]) != 0) for col in signs.T])
            cycles.append(changes / 2.0 / ((table.knots[-1] - table.knots[0]) / (2 * math.pi)))
        return np.concatenate(cycles) if cycles else np.zeros(0)

    def mechanisms(self):
        """Read by each mode's shape, not only its size: a mode that oscillates
        :data:`CYCLIC_PER_TURN` times a revolution or more is a cyclic gear or encoder error (of
        more orders than the Fourier series reached, or repeating over the travel rather than
        exactly each turn), a slower one a smooth error over the travel (cables winding up, a
        multi-turn encoder). Each of the two holds the physical range for its own modes and none
        for the others'."""
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        wide_lower, wide_upper = self.fit_range()
        fast = self.mode_cycles_per_turn() >= CYCLIC_PER_TURN
        return (Mechanism("gear_encoder_cyclic", "a cyclic error of the gear or the encoder (tooth mesh, interpolation) "
                          "at more cycles per turn than the Fourier series reached, or repeating over the travel "
                          "rather than exactly each turn", "compare the fitted curve's period with the gear's tooth "
                          "and wave-generator periods and the encoder's line count",
                          np.where(fast, lower, np.inf), np.where(fast, upper, -np.inf)),
                Mechanism("cable_windup", "a smooth error over the joint's travel: cables and hoses through the joint "
                          "pulling harder the further it turns, or an encoder whose nonlinearity repeats over several "
                          "turns", "drive the joint slowly over its travel with the dress pack loosened (or the cables "
                          "unclipped) and compare the error curve", np.where(fast, np.inf, lower),
                          np.where(fast, -np.inf, upper)),
                Mechanism("joint_slip", "a table mode above 1 mrad: a joint slipping on its shaft or a cable "
                          "snagging", "mark the joint's output against its housing and drive it over its travel",
                          wide_lower, wide_upper, False))

    def joint_columns(self, q) -> tuple[np.ndarray, np.ndarray]:
        """The parameter Jacobian in its compact form: each mode moves one joint only.

        Parameters
        ----------
        q : (N, n_joints) commanded joints [rad, m]

        Returns
        -------
        values : (N, k) d(dq_j)/d(theta_k) of the joint j = ``joint[k]`` [rad/rad]
        joint : (k,) int, the joint each parameter moves
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        m = self.modes_per_joint
        values = np.empty((q.shape[0], m * len(self.revolute)))
        for i, j in enumerate(self.revolute):
            values[:, i * m:(i + 1) * m] = self.table(j).values(q[:, j])
        return values, np.repeat(np.asarray(self.revolute, dtype=int), m)

    def joint_column_values(self, q: np.ndarray) -> tuple:
        """:meth:`joint_columns` with the values made a chunk of rows at a time when read
        (:class:`TableValues`): never the (N, k) array."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return TableValues(self, q), np.repeat(np.asarray(self.revolute, dtype=int), self.modes_per_joint)

    def joint_function(self, params, joint: str, angles: np.ndarray) -> np.ndarray:
        """(M,) the fitted table error [rad] of one joint at angles (M,) [rad]."""
        params = self.check_params(params)
        names, basis = self.joint_basis(joint, angles)
        index = {n: i for i, n in enumerate(self.parameter_names())}
        return basis @ params[[index[n] for n in names]] if names else np.zeros(np.shape(angles))

    def joint_basis(self, joint: str, angles: np.ndarray) -> tuple[list[str], np.ndarray]:
        """The parameters of one joint and their basis (M, k_j) at angles (M,) [rad]."""
        j = self.robot.joint_names.index(joint)
        if j not in self.revolute:
            return [], np.zeros((len(angles), 0))
        names = [f"angle_table.{joint}.m{i}" for i in range(1, self.modes_per_joint + 1)]
        return names, self.table(j).values(np.asarray(angles, dtype=float))


class TableValues:
    """An angle table's compact Jacobian values (N, k) at fixed joint values, made when rows are
    read: ``values[rows]`` (or ``values[rows, columns]``) is those rows of
    :meth:`AngleTable.joint_columns`, each joint's B-spline design (four non-zeros a row) times its
    modes. Held whole, a table of 208 modes a joint was 100 MB at 10^4 poses; ``np.asarray`` of it
    is that array."""

    ndim = 2
    dtype = np.dtype(float)

    def __init__(self, effect: AngleTable, q: np.ndarray):
        self.effect, self.q = effect, q
        self.shape = (q.shape[0], effect.n_params)

    def __getitem__(self, key):
        rows, columns = (key if isinstance(key, tuple) else (key, slice(None)))
        if isinstance(rows, (int, np.integer)):
            return self.effect.joint_columns(self.q[[rows]])[0][0, columns]
        return self.effect.joint_columns(self.q[rows])[0][:, columns]

    def __array__(self, dtype=None, copy=None):
        out = self.effect.joint_columns(self.q)[0]
        return out if dtype is None else out.astype(dtype)
