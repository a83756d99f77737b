"""A simulated "real robot" for prediction and compensation: hidden errors and a tracker.

Prediction and compensation only see its ``measure(q)``, so a real robot or another
simulation (``scripts/seed2_benchmark.py --truth simulate``) takes its place in one line.
The hidden truth is

* geometric errors: a random error vector x (placement twists, drive offsets, base
  and tool twists) of :class:`~tcr_accuracy.model.errors.ErrorModel`;
* gravity compliance: each joint moves by ``dq_j = -c_j * tau_j(q)`` [rad, m], with c_j
  its compliance [rad/(N m), m/N] and tau the torque gravity exerts on it
  (:func:`~tcr_accuracy.model.gravity.gravity_torque`: the robot's links plus a payload
  point mass at the TCP), so a joint moves along the torque its drive holds the arm with.
  That is against the sag of :mod:`tcr_accuracy.effects.compliance` (whose non-negative
  compliance cannot fit it); the stand-in has always moved this way, and keeps doing so
  that the benchmarks' hidden truth stays the one their figures come from;
* a laser tracker: isotropic Gaussian noise of std ``noise_m`` [m] on each axis.

So the TCP the tracker sees at commanded q is ``FK_x(q + dq(q)) + noise``. Stiffness is
a property of the robot and stays fixed when the payload changes
(:meth:`StandInRobot.with_payload`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.errors import ErrorModel
from ..model.gravity import gravity_torque
from ..model.kinematics import tcp_poses
from ..model.robot import REVOLUTE, RobotModel


@dataclass
class StandInRobot:
    """Hidden truth of a simulated robot and its tracker (see module docstring).

    Attributes
    ----------
    robot : RobotModel, the nominal robot (what the controller believes)
    x : (n_params,) hidden geometric error vector [m, rad]
    compliance : (n_joints,) joint compliance [rad/(N m) or m/N]
    payload_kg : point mass at the TCP [kg]
    noise_m : tracker noise std per axis [m]
    rng : Generator for the tracker noise
    """

    robot: RobotModel
    x: np.ndarray
    compliance: np.ndarray
    payload_kg: float
    noise_m: float
    rng: np.random.Generator
    error_model: ErrorModel = field(init=False)

    def __post_init__(self) -> None:
        self.error_model = ErrorModel(self.robot)

    def with_payload(self, payload_kg: float) -> "StandInRobot":
        """The same robot (same errors, stiffness, noise stream) carrying another payload."""
        return StandInRobot(self.robot, self.x, self.compliance, payload_kg, self.noise_m, self.rng)

    def joint_deflection(self, q: np.ndarray) -> np.ndarray:
        """(N, n) gravity deflection of each joint at commanded q (N, n) [rad, m]."""
        return -self.compliance * gravity_torque(self.robot, q, payload_kg=self.payload_kg)

    def true_positions(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) noise-free real TCP positions at commanded q (N, n) [m]."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return tcp_poses(self.robot, q + self.joint_deflection(q), self.x, self.error_model).position

    def true_errors(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) real minus nominal TCP position, noise-free [m]."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return self.true_positions(q) - tcp_poses(self.robot, q).position

    def measure(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) TCP positions as the tracker reports them [m]."""
        true = self.true_positions(q)
        return true + self.rng.normal(0.0, self.noise_m, size=true.shape)


def make_stand_in_robot(robot: RobotModel, rng: np.random.Generator, *, payload_kg: float = 150.0,
                        length_std_m: float = 2e-4, angle_std_rad: float = 2e-4,
                        drive_std_rad: float = 5e-4, deflection_rad: float = 1e-3,
                        noise_m: float = 2e-5) -> StandInRobot:
    """A random hidden truth of plausible size for ``robot``.

    Parameters
    ----------
    length_std_m, angle_std_rad : std of the placement, base and tool twists [m, rad]
    drive_std_rad : std of the revolute drive offsets [rad] (prismatic: 0.2 x this in m)
    deflection_rad : typical gravity deflection of a loaded joint [rad]; the compliance
        of joint j is ``deflection * U(0.5, 1.5) / rms(tau_j)`` with tau_j the gravity
        torque over random poses with the payload (prismatic joints: 0.1 x this in m).
    noise_m : tracker noise std per axis [m]
    """
    em = ErrorModel(robot)
    x = np.zeros(em.size)
    n = robot.n_joints
    placement = np.zeros((n, 6))
    placement[:, :3] = rng.normal(0.0, length_std_m, (n, 3))
    placement[:, 3:] = rng.normal(0.0, angle_std_rad, (n, 3))
    x[em.placement_slice] = placement.ravel()
    revolute = np.array([k == REVOLUTE for k in robot.joint_kinds])
    x[em.drive_slice] = rng.normal(0.0, 1.0, n) * np.where(revolute, drive_std_rad, 0.2 * drive_std_rad)
    for sl in (em.base_slice, em.tool_slice):
        x[sl] = np.concatenate([rng.normal(0.0, length_std_m, 3), rng.normal(0.0, angle_std_rad, 3)])
    lo = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -np.pi)
    hi = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, np.pi)
    lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)
    q = rng.uniform(lo, hi, (64, n))
    tau = gravity_torque(robot, q, payload_kg=payload_kg)
    rms = np.sqrt((tau**2).mean(axis=0))
    scale = np.where(revolute, deflection_rad, 0.1 * deflection_rad) * rng.uniform(0.5, 1.5, n)
    compliance = np.where(rms > 1e-6 * max(rms.max(), 1e-12), scale / np.maximum(rms, 1e-300), 0.0)
    return StandInRobot(robot, x, compliance, payload_kg, noise_m, rng)
