"""Checks of training data that the estimators share."""

from __future__ import annotations

from ..exceptions import InputError


def check_enough_points(n_samples: int, n_features: int, who: str) -> None:
    """Raise InputError unless there are more training rows than joints (features)."""
    if n_samples <= n_features:
        raise InputError(
            f"{who}: needs more training points than joints, got n_samples = {n_samples} for "
            f"{n_features} joints; measure at least {n_features + 1} (the seed used 160 for 6)")


def check_joints_and_position_errors(robot, X, y, who: str) -> None:
    """Raise InputError unless there is a robot, X is (n, robot.n_joints) joint values and y
    is (n, 3) position errors [m], as the robot-model estimators need."""
    if robot is None:
        raise InputError(f"{who} needs a robot")
    if y.ndim != 2 or y.shape[1] != 3 or X.shape[1] != robot.n_joints:
        raise InputError(f"{who}: needs joint values (n, {robot.n_joints}) and position errors (n, 3), got "
                         f"{X.shape} and {y.shape}")
