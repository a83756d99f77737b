"""The geometric error model: a flat, named parameter vector and what it does to a robot.

Layout of the parameter vector ``x`` (shape (n_params,), SI units), for a robot
with ``n`` joints:

=============  ===========  ==========================================================
slice          group        meaning
=============  ===========  ==========================================================
0 .. 6n        placement    twist xi_j = (dx, dy, dz, rx, ry, rz) on each joint placement,
                            applied on the right: ``parentMjoint <- parentMjoint * exp6(xi_j)``
                            (so expressed in the joint's own frame) [m, rad]
6n .. 7n       drive        joint drive offset: the joint sits at ``q + dq`` [rad or m]
7n .. 7n+6     base         twist on the base frame, applied on the left of the first
                            joint placement(s): ``exp6(xi_base) * parentMjoint`` [m, rad]
7n+6 .. 7n+12  tool         twist on the TCP frame: ``jointMtool <- jointMtool * exp6(xi_tool)``
=============  ===========  ==========================================================

Names are ``<joint>.dx`` .. ``<joint>.rz``, ``<joint>.drive``, ``base.dx`` .. and
``tool.dx`` ... To first order in the twist, ``exp6(xi)`` is the seed paper's error
screw; it stays exact for errors of any size.

An :class:`ErrorBudget` describes the random error *sources* (a link length error, a
drive error, an axis tilt, ...) with their distributions and how each maps linearly
onto ``x``. :func:`seed_budget` gives the seed paper's Table 1 and Table 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..random_state import renamed_keyword
from .robot import PRISMATIC, REVOLUTE, RobotModel

PLACEMENT_COMPONENTS = ("dx", "dy", "dz", "rx", "ry", "rz")
GROUPS = ("placement", "drive", "base", "tool")


@dataclass(frozen=True)
class ErrorParameter:
    """One entry of the error parameter vector."""

    name: str  # e.g. "j3.dy", "j2.drive", "base.rz"
    group: str  # one of GROUPS
    owner: str  # joint name, "base" or "tool"
    component: str  # "dx".."rz" or "drive"
    unit: str  # "m" or "rad"


class ErrorModel:
    """Named layout of the error parameters of one robot (see module docstring).

    Parameters
    ----------
    robot : RobotModel
        The nominal robot. It is never modified.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> em = tcr.ErrorModel(tcr.load_robot("ur5"))
    >>> em.size, em.names[0]
    (54, 'shoulder_pan_joint.dx')
    """

    def __repr__(self) -> str:
        return f"ErrorModel({self.robot.name!r}, {self.size} parameters over {self.n_joints} joints)"

    def __init__(self, robot: RobotModel):
        self.robot = robot
        n = robot.n_joints
        self.n_joints = n
        params: list[ErrorParameter] = []
        for name in robot.joint_names:
            for c in PLACEMENT_COMPONENTS:
                params.append(ErrorParameter(f"{name}.{c}", "placement", name, c, _unit(c)))
        for name, kind in zip(robot.joint_names, robot.joint_kinds):
            params.append(ErrorParameter(f"{name}.drive", "drive", name, "drive",
                                         "rad" if kind == REVOLUTE else "m"))
        for owner in ("base", "tool"):
            for c in PLACEMENT_COMPONENTS:
                params.append(ErrorParameter(f"{owner}.{c}", owner, owner, c, _unit(c)))
        self.parameters: tuple[ErrorParameter, ...] = tuple(params)
        self._index = {p.name: i for i, p in enumerate(self.parameters)}
        self.placement_slice = slice(0, 6 * n)
        self.drive_slice = slice(6 * n, 7 * n)
        self.base_slice = slice(7 * n, 7 * n + 6)
        self.tool_slice = slice(7 * n + 6, 7 * n + 12)
        self.root_joints = [j - 1 for j in range(1, robot.model.njoints) if robot.model.parents[j] == 0]

    # -- naming ----------------------------------------------------------------------
    @property
    def size(self) -> int:
        return len(self.parameters)

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise InputError(
                f"unknown error parameter {name!r}; parameters look like "
                f"{self.parameters[0].name}, {self.robot.joint_names[0]}.drive, base.rz, tool.dz"
            ) from None

    def group_indices(self, group: str) -> np.ndarray:
        return np.array([i for i, p in enumerate(self.parameters) if p.group == group], dtype=int)

    def zeros(self) -> np.ndarray:
        return np.zeros(self.size)

    # -- views -------------------------------------------------------------------------
    def split(self, x: np.ndarray) -> "ErrorComponents":
        """Views of x (..., n_params) as placement (..., n, 6), drive (..., n), base, tool (..., 6)."""
        x = np.asarray(x, dtype=float)
        if x.shape[-1] != self.size:
            raise InputError(f"error vector has {x.shape[-1]} entries, the model needs {self.size}")
        lead = x.shape[:-1]
        return ErrorComponents(
            placement=x[..., self.placement_slice].reshape(*lead, self.n_joints, 6),
            drive=x[..., self.drive_slice],
            base=x[..., self.base_slice],
            tool=x[..., self.tool_slice],
        )

    # -- perturbed model ---------------------------------------------------------------
    def perturbed_placements(self, x: np.ndarray) -> tuple[list[pin.SE3], pin.SE3]:
        """As-built ``parentMjoint`` for every joint and ``jointMtool``, for one x (n_params,).

        Drive offsets are folded into the placements: for a 1-DoF joint with a
        constant motion axis S, ``joint(q + dq) = exp6(S dq) * joint(q)``.
        """
        parts = self.split(x)
        axes = self.robot.motion_axes
        base = pin.exp6(parts.base)
        placements = []
        for j, nominal in enumerate(self.robot.joint_placements):
            placement = nominal * pin.exp6(parts.placement[j]) * pin.exp6(axes[j] * parts.drive[j])
            if j in self.root_joints:
                placement = base * placement
            placements.append(placement)
        tool = self.robot.tool_placement * pin.exp6(parts.tool)
        return placements, tool

    def perturbed_robot(self, x: np.ndarray, name: str | None = None) -> RobotModel:
        """A new RobotModel whose Pinocchio model is the as-built robot for x (n_params,).

        The nominal robot is left untouched.
        """
        placements, tool = self.perturbed_placements(x)
        model = pin.Model(self.robot.model)
        for j, placement in enumerate(placements):
            model.jointPlacements[j + 1] = placement
        frame = model.frames[self.robot.tool_frame_id]
        frame.placement = tool
        model.frames[self.robot.tool_frame_id] = frame
        return self.robot.with_model(model, name=name or f"{self.robot.name}_as_built")


@dataclass(frozen=True)
class ErrorComponents:
    placement: np.ndarray  # (..., n_joints, 6) [m, rad]
    drive: np.ndarray  # (..., n_joints) [rad or m]
    base: np.ndarray  # (..., 6)
    tool: np.ndarray  # (..., 6)


def _unit(component: str) -> str:
    return "m" if component.startswith("d") else "rad"


# ---------------------------------------------------------------------------------------
# Error sources and their distributions
# ---------------------------------------------------------------------------------------
DISTRIBUTIONS = ("normal", "uniform", "truncnormal")


@dataclass(frozen=True)
class ErrorSource:
    """A scalar random error and the direction it moves the parameter vector.

    ``x = sum_k value_k * direction_k`` over the sources of a budget.

    Attributes
    ----------
    name : str
        e.g. ``"l3 length"``, ``"j2 drive"``, ``"j5 axis tilt ry"``.
    group : str
        ``link_length``, ``drive``, ``axis_deflection`` or a parameter group.
    direction : ndarray of shape (n_params,)
    unit : str
        ``m`` or ``rad``: the unit of the source's value.
    distribution : str
        ``normal`` (mean, std), ``uniform`` (low, high) or ``truncnormal`` (mean,
        std, low, high).
    """

    name: str
    group: str
    direction: np.ndarray
    unit: str
    distribution: str = "normal"
    mean: float = 0.0
    std: float = 0.0
    low: float = -math.inf
    high: float = math.inf

    def __post_init__(self) -> None:
        if self.distribution not in DISTRIBUTIONS:
            raise InputError(
                f"error source {self.name}: unknown distribution {self.distribution!r} "
                f"(use one of {', '.join(DISTRIBUTIONS)})"
            )
        if not (self.std >= 0.0) or not math.isfinite(self.std):
            raise InputError(f"error source {self.name}: spread must be finite and >= 0, got {self.std}")
        if self.distribution == "uniform" and not (self.low <= self.high and math.isfinite(self.low)
                                                   and math.isfinite(self.high)):
            raise InputError(f"error source {self.name}: uniform needs finite low <= high")
        if self.distribution == "truncnormal" and not self.low < self.high:
            raise InputError(f"error source {self.name}: truncnormal needs low < high")

    @property
    def variance(self) -> float:
        """Variance of the source's value [unit^2]."""
        if self.distribution == "normal":
            return self.std**2
        if self.distribution == "uniform":
            return (self.high - self.low) ** 2 / 12.0
        from scipy import stats

        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        return float(stats.truncnorm.var(a, b, loc=self.mean, scale=self.std))

    @property
    def expectation(self) -> float:
        if self.distribution == "uniform":
            return 0.5 * (self.low + self.high)
        if self.distribution == "normal":
            return self.mean
        from scipy import stats

        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        return float(stats.truncnorm.mean(a, b, loc=self.mean, scale=self.std))

    @renamed_keyword("rng", "random_state")
    def sample(self, n: int, random_state=None) -> np.ndarray:
        """(n,) random values of the source.

        Parameters
        ----------
        n : int
        random_state : int, numpy.random.Generator or None, default=None
            Drawn from (a Generator: its stream goes on; formerly ``rng``).

        Returns
        -------
        ndarray of shape (n,)
        """
        rng = np.random.default_rng(random_state)
        if self.distribution == "normal":
            return self.mean + self.std * rng.standard_normal(n)
        if self.distribution == "uniform":
            return rng.uniform(self.low, self.high, n)
        from scipy import stats

        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        return stats.truncnorm.ppf(rng.uniform(size=n), a, b, loc=self.mean, scale=self.std)

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """Values at probabilities u in (0, 1) (inverse CDF), e.g. for Sobol sampling."""
        from scipy import stats

        if self.distribution == "normal":
            return stats.norm.ppf(u, loc=self.mean, scale=self.std) if self.std > 0 else np.full_like(u, self.mean)
        if self.distribution == "uniform":
            return self.low + (self.high - self.low) * u
        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        return stats.truncnorm.ppf(u, a, b, loc=self.mean, scale=self.std)


@dataclass
class ErrorBudget:
    """A set of independent error sources for one robot.

    Parameters
    ----------
    error_model : ErrorModel
        The layout of the error parameters the sources move.
    sources : list of ErrorSource
        The independent sources (distribution, spread [SI], the parameters they move).
    name : str
        Label for reports (``table1``, a budget file's name).

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> budget = tcr.seed_budget(tcr.load_robot(), "table2")
    >>> budget.sample(3, random_state=0).shape  # three as-built robots' error vectors
    (3, 54)
    """

    error_model: ErrorModel
    sources: list[ErrorSource] = field(default_factory=list)
    name: str = "custom"

    def __repr__(self) -> str:
        touched = int(np.count_nonzero(np.any(self.matrix != 0.0, axis=1))) if self.sources else 0
        return (f"ErrorBudget({self.name!r}, robot {self.error_model.robot.name!r}, {len(self.sources)} sources "
                f"moving {touched} of {self.error_model.size} parameters)")

    @property
    def matrix(self) -> np.ndarray:
        """(n_params, n_sources) map from source values to the parameter vector."""
        if not self.sources:
            return np.zeros((self.error_model.size, 0))
        return np.stack([s.direction for s in self.sources], axis=1)

    @property
    def source_names(self) -> list[str]:
        return [s.name for s in self.sources]

    @renamed_keyword("rng", "random_state")
    def sample_sources(self, n: int, random_state=None) -> np.ndarray:
        """(n, n_sources) independent draws, one column per source.

        Parameters
        ----------
        n : int
        random_state : int, numpy.random.Generator or None, default=None
            Drawn from (a Generator: its stream goes on; formerly ``rng``).

        Returns
        -------
        ndarray of shape (n, n_sources)
        """
        if not self.sources:
            return np.zeros((n, 0))
        rng = np.random.default_rng(random_state)
        return np.stack([s.sample(n, rng) for s in self.sources], axis=1)

    @renamed_keyword("rng", "random_state")
    def sample(self, n: int, random_state=None) -> np.ndarray:
        """(n, n_params) error parameter vectors.

        Parameters
        ----------
        n : int
        random_state : int, numpy.random.Generator or None, default=None
            Drawn from (a Generator: its stream goes on; formerly ``rng``).

        Returns
        -------
        ndarray of shape (n, n_params)
        """
        return self.sample_sources(n, random_state) @ self.matrix.T

    def parameter_mean(self) -> np.ndarray:
        """(n_params,) expectation of x."""
        return self.matrix @ np.array([s.expectation for s in self.sources])

    def parameter_covariance(self) -> np.ndarray:
        """(n_params, n_params) covariance of x (sources are independent)."""
        a = self.matrix
        return (a * np.array([s.variance for s in self.sources])) @ a.T

    def scaled(self, factor: float, groups: set[str] | None = None) -> "ErrorBudget":
        """A copy with every spread (or only those of ``groups``) multiplied by factor."""
        out = []
        for s in self.sources:
            if groups is None or s.group in groups:
                s = ErrorSource(s.name, s.group, s.direction, s.unit, s.distribution,
                                s.mean * factor, s.std * factor, s.low * factor, s.high * factor)
            out.append(s)
        return ErrorBudget(self.error_model, out, name=f"{self.name}*{factor:g}")


# ---------------------------------------------------------------------------------------
# The seed paper's presets
# ---------------------------------------------------------------------------------------
#: Table 1 of the seed: one spread per error kind [m, rad].
SEED_TABLE1 = {
    "link_length": 0.2e-3,  # linkage dimension error, 0.2 mm
    "drive_prismatic": 0.3e-3,  # driving error of the moving joint, 0.3 mm
    "drive_revolute": 0.0087,  # driving error of rotating joints [rad] (0.5 deg)
    "axis_deflection": 0.00435,  # joint axis deflection [rad]
}

#: Table 2 of the seed: per link and per joint spreads [m, rad]. The seed leaves joint 6's
#: drive spread out; we take 0.5 deg, the same as joint 5, since both are driven by
#: oscillating hydraulic cylinders of the same kind.
SEED_TABLE2 = {
    "link_length": [0.17e-3, 0.15e-3, 0.20e-3, 0.25e-3, 0.15e-3, 0.15e-3],
    "drive": [math.radians(0.3), math.radians(0.3), math.radians(0.1548), 0.25e-3,
              math.radians(0.5), math.radians(0.5)],
}


def link_length_direction(robot: RobotModel, j: int, error_model: ErrorModel) -> np.ndarray | None:
    """(n_params,) direction of a length error of the link ending at joint j.

    The link runs along the nominal placement's translation; a length error moves
    the joint along it. Expressed in the joint's frame (the placement twist's frame).
    None when the placement has no translation (coincident joint origins).
    """
    placement = robot.joint_placements[j]
    t = placement.translation
    norm = float(np.linalg.norm(t))
    if norm < 1e-9:
        return None
    direction = np.zeros(error_model.size)
    local = placement.rotation.T @ (t / norm)
    start = error_model.index(f"{robot.joint_names[j]}.dx")
    direction[start:start + 3] = local
    return direction


def axis_deflection_directions(robot: RobotModel, j: int, error_model: ErrorModel
                               ) -> list[tuple[str, np.ndarray]]:
    """Two (label, direction) pairs tilting joint j's axis about the perpendicular axes."""
    candidates = robot.axis_perpendiculars(j)
    out = []
    start = error_model.index(f"{robot.joint_names[j]}.rx")
    for u in candidates[:2]:
        direction = np.zeros(error_model.size)
        direction[start:start + 3] = u
        label = "rx ry rz".split()[int(np.argmax(np.abs(u)))] if np.max(np.abs(u)) > 1 - 1e-12 else "tilt"
        out.append((label, direction))
    return out


def drive_source(robot: RobotModel, j: int, error_model: ErrorModel, std: float) -> ErrorSource:
    """A normal drive error of joint j with the given spread [rad or m]."""
    name = robot.joint_names[j]
    direction = np.zeros(error_model.size)
    direction[error_model.index(f"{name}.drive")] = 1.0
    unit = "rad" if robot.joint_kinds[j] == REVOLUTE else "m"
    return ErrorSource(f"{name} drive", "drive", direction, unit, std=std)


#: The joint kinds the seed's Table 2 lists, in order: the tool-changer's 5R + 1P.
TABLE2_JOINT_KINDS = [REVOLUTE, REVOLUTE, REVOLUTE, PRISMATIC, REVOLUTE, REVOLUTE]


def default_preset(robot: RobotModel) -> str:
    """The error preset an analysis takes when none is named: the seed's ``table2`` for a
    robot with the tool-changer's joints, else ``table1``, which is built from any robot's
    own joints (every link length, drive and axis tilt with the seed's Table 1 spreads)."""
    return "table2" if list(robot.joint_kinds) == TABLE2_JOINT_KINDS else "table1"


def seed_budget(robot: RobotModel, preset: str) -> ErrorBudget:
    """The seed paper's error distributions as an :class:`ErrorBudget`.

    Parameters
    ----------
    robot : RobotModel
        The robot the budget applies to.
    preset : str
        ``table1`` or ``table2`` (below).

    Returns
    -------
    ErrorBudget
        One independent source per spread.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> budget = tcr.seed_budget(tcr.load_robot(), "table2")
    >>> budget.name
    'table2'

    ``table1``: every link length 0.2 mm, prismatic drives 0.3 mm, revolute drives
    0.0087 rad, and every revolute joint's axis tilted about its two perpendicular
    axes with 0.00435 rad (the seed deflects joints 1, 2, 3, 5, 6; Eq. 35). Applies
    to any robot. ``table2``: the per-link and per-joint spreads of Table 2 (link
    lengths and drives; Table 2 has no axis deflection). Needs a robot with the
    tool-changer's six joints.
    """
    error_model = ErrorModel(robot)
    sources: list[ErrorSource] = []
    kinds = robot.joint_kinds
    if preset == "table1":
        for j, name in enumerate(robot.joint_names):
            direction = link_length_direction(robot, j, error_model)
            if direction is not None:
                sources.append(ErrorSource(f"{name} link length", "link_length", direction, "m",
                                           std=SEED_TABLE1["link_length"]))
        for j in range(robot.n_joints):
            std = SEED_TABLE1["drive_revolute" if kinds[j] == REVOLUTE else "drive_prismatic"]
            sources.append(drive_source(robot, j, error_model, std))
        for j, name in enumerate(robot.joint_names):
            if kinds[j] != REVOLUTE:
                continue
            for label, direction in axis_deflection_directions(robot, j, error_model):
                sources.append(ErrorSource(f"{name} axis tilt {label}", "axis_deflection", direction, "rad",
                                           std=SEED_TABLE1["axis_deflection"]))
    elif preset == "table2":
        if list(kinds) != TABLE2_JOINT_KINDS:
            raise InputError(
                f"preset=table2: the seed's Table 2 lists the tool-changer's joints (5R + 1P); "
                f"robot {robot.name} has {len(kinds)} joints ({', '.join(k[0].upper() for k in kinds)}); "
                "use preset=table1", parameter="preset", value=preset
            )
        for j, name in enumerate(robot.joint_names):
            direction = link_length_direction(robot, j, error_model)
            if direction is not None:
                sources.append(ErrorSource(f"l{j + 1} link length", "link_length", direction, "m",
                                           std=SEED_TABLE2["link_length"][j]))
        for j in range(robot.n_joints):
            sources.append(drive_source(robot, j, error_model, SEED_TABLE2["drive"][j]))
    else:
        raise InputError(f"preset={preset}: unknown preset (known: table1, table2)", parameter="preset", value=preset)
    return ErrorBudget(error_model, sources, name=preset)
