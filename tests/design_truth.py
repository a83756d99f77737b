"""A hidden UR10 for the pose-design tests and ``scripts/bench_design.py``, written on Pinocchio alone.

Joint-placement error screws and encoder offsets (:func:`hidden_robot.geometric_errors`), each joint
sagging with the gravity torque that holds it (``delta = -C g(q)``, ``g`` from
``pin.computeGeneralizedGravity``), and a gear error of two harmonics of the joint's own angle on the
first three joints; the tracker reads the TCP in a frame of its own with 0.02 mm noise per axis.
Nothing here imports the project's effect classes: the design and the diagnosis never see this truth.
"""

from __future__ import annotations

import numpy as np

from hidden_robot import HiddenRobot, fixed_tracker, geometric_errors, in_tracker

#: the tracker's noise per axis [m]
NOISE_M = 2e-5


def hidden_ur10_errors(robot, rng: np.random.Generator):
    """The measuring function of a hidden UR10: ``measure(q (N, 6) [rad], rng) -> (N, 3)`` tracker readings [m]."""
    offsets, placements = geometric_errors(robot, rng, offset_deg=0.02, offset_mm=0.0, placement_mm=0.15,
                                           placement_deg=0.01)
    hidden = HiddenRobot(robot, placement_errors=placements)
    compliance = rng.uniform(0.5, 1.5, robot.n_joints) * np.array([1.0, 1.0, 1.0, 3.0, 3.0, 3.0]) * 1e-6  # [rad/Nm]
    gear = np.zeros((robot.n_joints, 4))  # a1, phase1, a2, phase2 per joint [rad]
    gear[:3] = np.column_stack([rng.uniform(1.5e-4, 3e-4, 3), rng.uniform(0, 2 * np.pi, 3),
                                rng.uniform(0.7e-4, 1.5e-4, 3), rng.uniform(0, 2 * np.pi, 3)])
    tracker = fixed_tracker()

    def measure(q: np.ndarray, noise_rng: np.random.Generator) -> np.ndarray:
        q = np.atleast_2d(q)
        sag = -compliance * hidden.holding_torque(q, np.zeros(len(q)))
        cyclic = gear[:, 0] * np.sin(q + gear[:, 1]) + gear[:, 2] * np.sin(2 * q + gear[:, 3])
        real = q + offsets + sag + cyclic
        base = hidden.positions(real, [robot.tool_frame])[robot.tool_frame]
        return in_tracker(tracker, base) + noise_rng.normal(0.0, NOISE_M, base.shape)

    return measure
