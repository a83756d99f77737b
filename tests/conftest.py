"""Shared fixtures: models are built in-process (no network, no files outside the repo)."""

from pathlib import Path

import numpy as np
import pytest

from tcr_accuracy.robot import load_robot

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def tool_changer():
    return load_robot()


@pytest.fixture(scope="session")
def ur5():
    return load_robot("ur5")


def random_joint_values(robot, n, rng, span=np.pi):
    """(n, n_joints) joint values inside the limits (unbounded joints within +-span)."""
    lo = np.where(np.isnan(robot.lower_limits), -span, np.maximum(robot.lower_limits, -span))
    hi = np.where(np.isnan(robot.upper_limits), span, np.minimum(robot.upper_limits, span))
    return rng.uniform(lo, hi, size=(n, robot.n_joints))
