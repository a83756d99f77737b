"""Random joint clearance (play) as SE3 perturbations of the joint placements.

The seed paper (Qian et al. 2022, Eq. 27-43, Table 4) models the play of each
revolute joint's journal inside its sleeve with four random quantities:

- an axial movement ``d`` along the joint axis [m],
- a radial "clearance rod" of length ``s`` at a uniform random angle ``theta`` in
  [0, 2 pi), i.e. a translation perpendicular to the axis [m],
- a spatial deflection of the axis by small angles ``w_x`` and ``w_y`` about the two
  axes perpendicular to it [rad].

Here every joint's play is one rigid displacement of the journal frame relative to
the sleeve, inserted into the joint placement (see :mod:`tcr_accuracy.model.errors`):

``parentMjoint <- parentMjoint * Trans(d a + s (cos(theta) u + sin(theta) v)) * Rot(w_x u + w_y v)``

with ``a`` the joint axis and ``(u, v)`` the perpendicular pair in the joint frame.
For the tool-changer, the pair is (x, y) for the z-axis joints j1 and j6 (the seed's
horizontal plane) and (y, z) for the x-axis joints j2, j3 and j5 (the seed's vertical
plane, Eq. 42). The displacement is turned into the exact placement twist
``xi = log6(...)`` so that samples plug into the same Monte Carlo engine as any
other error budget; the map from (d, s, theta, w) to x is nonlinear, so the sampler
produces x directly instead of being a linear :class:`~tcr_accuracy.model.errors.ErrorBudget`.

The seed instead adds the radial vectors to the TCP position afterwards (Eq. 42-43);
:func:`radial_offset_added` gives that vector so the two can be compared: they agree
exactly when the deflections are zero and differ by about ``|w| s`` otherwise.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .errors import ErrorModel
from ..exceptions import InputError
from .robot import REVOLUTE, RobotModel

#: Table 4 of the seed: standard deviations of the clearance quantities [m, rad].
SEED_TABLE4 = {
    "axial_std": 0.2e-3,  # d_i, axial movement
    "radial_std": 0.5e-3,  # s_i, length of the clearance rod
    "deflection_std": 0.087,  # w_xi and w_yi, spatial deflection [rad] (about 5 deg)
}


@dataclass(frozen=True)
class ClearanceSample:
    """Raw clearance quantities for n samples and k joints (each (n, k))."""

    axial: np.ndarray  # d [m]
    radial: np.ndarray  # s [m] (signed, normal with mean 0 as in Table 4)
    angle: np.ndarray  # theta [rad], uniform in [0, 2 pi)
    deflection_u: np.ndarray  # w_x [rad], about u
    deflection_v: np.ndarray  # w_y [rad], about v


def _inverse_left_jacobian_apply(w: np.ndarray, t: np.ndarray) -> np.ndarray:
    """J(w)^-1 t for rotation vectors w (n, 3) and vectors t (n, 3), batched.

    J is the left Jacobian of SO(3) that ``pin.exp6`` uses: exp6((v, w)) has
    translation J(w) v. Closed form
    ``J^-1 = I - [w]/2 + (1/t^2 - (1 + cos t) / (2 t sin t)) [w]^2`` (t = |w|), with
    its Taylor series 1/12 + t^2/720 for small angles.
    """
    theta_sq = np.einsum("ni,ni->n", w, w)
    theta = np.sqrt(theta_sq)
    small = theta < 1e-3
    safe = np.where(small, 1.0, theta)
    coef = np.where(small, 1.0 / 12.0 + theta_sq / 720.0,
                    1.0 / safe**2 - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe)))
    wxt = np.cross(w, t)
    return t - 0.5 * wxt + coef[:, None] * np.cross(w, wxt)


@dataclass(frozen=True)
class ClearanceModel:
    """Random joint play of the revolute joints of a robot, sampled as error vectors x.

    Parameters
    ----------
    error_model : ErrorModel
        Layout of x (its robot is the nominal robot).
    joints : tuple of int, optional
        Joint indices with play; default every revolute joint (for the tool-changer:
        j1, j2, j3, j5 and j6 as in the seed).
    axial_std, radial_std : float
        Standard deviations of d and s [m] (normal, mean 0).
    deflection_std : float
        Standard deviation of w_x and w_y [rad] (normal, mean 0).
    name : str

    Use :meth:`from_robot` for the seed's Table 4, ``dataclasses.replace`` (or
    :meth:`with_spreads`) for other spreads.
    """

    error_model: ErrorModel
    joints: tuple[int, ...]
    axial_std: float = SEED_TABLE4["axial_std"]
    radial_std: float = SEED_TABLE4["radial_std"]
    deflection_std: float = SEED_TABLE4["deflection_std"]
    name: str = "clearance"

    def __post_init__(self) -> None:
        for key in ("axial_std", "radial_std", "deflection_std"):
            value = getattr(self, key)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"clearance {key}: must be finite and >= 0, got {value}")
        robot = self.error_model.robot
        for j in self.joints:
            if not 0 <= j < robot.n_joints or robot.joint_kinds[j] != REVOLUTE:
                raise InputError(f"clearance: joint index {j} is not a revolute joint of {robot.name}")

    @classmethod
    def from_robot(cls, robot: RobotModel, error_model: ErrorModel | None = None, **spreads) -> "ClearanceModel":
        """Play on every revolute joint with the seed's Table 4 spreads (override by keyword)."""
        error_model = error_model or ErrorModel(robot)
        joints = tuple(j for j, kind in enumerate(robot.joint_kinds) if kind == REVOLUTE)
        return cls(error_model=error_model, joints=joints, **spreads)

    def with_spreads(self, **spreads) -> "ClearanceModel":
        """A copy with some of axial_std, radial_std, deflection_std replaced."""
        return dataclasses.replace(self, **spreads)

    @property
    def robot(self) -> RobotModel:
        return self.error_model.robot

    def frames(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint axis a, and perpendicular u, v, each (k, 3), in each joint's frame."""
        axes = np.array([self.robot.joint_axis(j) for j in self.joints]).reshape(-1, 3)
        pairs = [self.robot.axis_perpendiculars(j) for j in self.joints]
        u = np.array([p[0] for p in pairs]).reshape(-1, 3)
        v = np.array([p[1] for p in pairs]).reshape(-1, 3)
        return axes, u, v

    # -- sampling ------------------------------------------------------------------
    def sample_components(self, n: int, rng: np.random.Generator) -> ClearanceSample:
        """(n, k) draws of d, s, theta, w_x, w_y (k = number of joints with play)."""
        k = len(self.joints)
        return ClearanceSample(
            axial=self.axial_std * rng.standard_normal((n, k)),
            radial=self.radial_std * rng.standard_normal((n, k)),
            angle=rng.uniform(0.0, 2.0 * np.pi, (n, k)),
            deflection_u=self.deflection_std * rng.standard_normal((n, k)),
            deflection_v=self.deflection_std * rng.standard_normal((n, k)),
        )

    def joint_displacements(self, c: ClearanceSample, include_radial: bool = True
                            ) -> tuple[np.ndarray, np.ndarray]:
        """Translation t (n, k, 3) [m] and rotation vector w (n, k, 3) [rad] per joint, joint frame."""
        a, u, v = self.frames()
        radial = c.radial if include_radial else np.zeros_like(c.radial)
        t = (c.axial[..., None] * a + (radial * np.cos(c.angle))[..., None] * u
             + (radial * np.sin(c.angle))[..., None] * v)
        w = c.deflection_u[..., None] * u + c.deflection_v[..., None] * v
        return t, w

    def to_parameters(self, c: ClearanceSample, include_radial: bool = True) -> np.ndarray:
        """(n, n_params) exact placement twists: exp6(xi) = Trans(t) * Rot(exp3(w))."""
        t, w = self.joint_displacements(c, include_radial)
        n, k = t.shape[:2]
        lin = _inverse_left_jacobian_apply(w.reshape(-1, 3), t.reshape(-1, 3)).reshape(n, k, 3)
        x = np.zeros((n, self.error_model.size))
        placement = x[:, self.error_model.placement_slice].reshape(n, self.robot.n_joints, 6)
        placement[:, list(self.joints), :3] = lin
        placement[:, list(self.joints), 3:] = w
        x[:, self.error_model.placement_slice] = placement.reshape(n, -1)
        return x

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, n_params) error vectors (the sampler interface of the Monte Carlo engine)."""
        return self.to_parameters(self.sample_components(n, rng))

    # -- first-order description -----------------------------------------------------
    def parameter_mean(self) -> np.ndarray:
        """(n_params,) expectation of x (zero: every quantity is symmetric)."""
        return np.zeros(self.error_model.size)

    def parameter_covariance(self) -> np.ndarray:
        """(n_params, n_params) covariance of the linearised x = (t, w) per joint.

        Exact for the rotation part; for the translation part it drops the
        second-order coupling ``-w x t / 2`` of the log map. With theta uniform,
        (s cos theta, s sin theta) has covariance ``radial_std^2 / 2`` on u and v.
        """
        a, u, v = self.frames()
        cov = np.zeros((self.error_model.size, self.error_model.size))
        for idx, j in enumerate(self.joints):
            start = self.error_model.index(f"{self.robot.joint_names[j]}.dx")
            plane = np.outer(u[idx], u[idx]) + np.outer(v[idx], v[idx])
            cov[start:start + 3, start:start + 3] = (self.axial_std**2 * np.outer(a[idx], a[idx])
                                                     + 0.5 * self.radial_std**2 * plane)
            cov[start + 3:start + 6, start + 3:start + 6] = self.deflection_std**2 * plane
        return cov


def joint_frames_world(robot: RobotModel, q: np.ndarray) -> list[pin.SE3]:
    """Nominal world placement of each joint frame at zero joint motion ``oMparent * parentMjoint``.

    This is the frame in which a clearance displacement of joint j is expressed.
    """
    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, robot.to_pinocchio_q(q))
    out = []
    for j in range(1, model.njoints):
        out.append(data.oMi[model.parents[j]] * model.jointPlacements[j])
    return out


def radial_offset_added(model: ClearanceModel, q: np.ndarray, c: ClearanceSample) -> np.ndarray:
    """(n, 3) the seed's Eq. 42-43: radial clearance vectors summed in the base frame [m].

    Each joint's radial vector ``s (cos theta u + sin theta v)`` is rotated into the
    base frame with the NOMINAL orientation of its joint frame at q and the vectors
    are added to the TCP position afterwards. Without deflections, a pure
    translation of a joint frame moves every later frame by exactly this vector, so
    the sum equals the SE3 model's position change; with deflections the two differ
    by terms of order ``|w| s``.
    """
    frames = joint_frames_world(model.robot, q)
    _, u, v = model.frames()
    out = np.zeros((c.radial.shape[0], 3))
    for idx, j in enumerate(model.joints):
        local = ((c.radial[:, idx] * np.cos(c.angle[:, idx]))[:, None] * u[idx]
                 + (c.radial[:, idx] * np.sin(c.angle[:, idx]))[:, None] * v[idx])
        out += local @ frames[j].rotation.T
    return out
