"""Monte Carlo accuracy of the TCP under random error sources, and its reliability.

Samples an :class:`~tcr_accuracy.errors.ErrorBudget` in chunks (memory does not grow
with the sample count), runs the batched kinematics on each chunk and keeps running
sums, so the statistics of 10 million samples cost the memory of one chunk.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import ErrorBudget
from .kinematics import pose_error, tcp_poses

#: Default chunk of samples processed at once.
CHUNK = 100_000


@dataclass
class RunningStats:
    """Mean, std, min and max of a stream of (n, k) arrays, column by column."""

    count: int = 0
    total: np.ndarray | None = None
    total_sq: np.ndarray | None = None
    minimum: np.ndarray | None = None
    maximum: np.ndarray | None = None

    def add(self, values: np.ndarray) -> None:
        values = np.asarray(values, dtype=float)
        if self.total is None:
            k = values.shape[1]
            self.total, self.total_sq = np.zeros(k), np.zeros(k)
            self.minimum, self.maximum = np.full(k, np.inf), np.full(k, -np.inf)
        self.count += values.shape[0]
        self.total += values.sum(axis=0)
        self.total_sq += (values * values).sum(axis=0)
        self.minimum = np.minimum(self.minimum, values.min(axis=0))
        self.maximum = np.maximum(self.maximum, values.max(axis=0))

    @property
    def mean(self) -> np.ndarray:
        return self.total / self.count

    @property
    def std(self) -> np.ndarray:
        """Sample standard deviation (ddof = 1)."""
        n = self.count
        var = (self.total_sq - self.total**2 / n) / max(n - 1, 1)
        return np.sqrt(np.maximum(var, 0.0))


#: Columns of the statistics: position errors [m] then ZYX Euler angle errors [rad].
STAT_COLUMNS = ("dx", "dy", "dz", "norm", "d_alpha_z", "d_beta_y", "d_gamma_x")


@dataclass
class MonteCarloResult:
    """Statistics of the TCP pose error over the samples.

    stats : RunningStats over the columns STAT_COLUMNS (SI units)
    position_tolerances : (k,) tolerances T [m] and position_reliability (k,) P(|dP| < T)
    angle_tolerance : R [rad] and angle_reliability (3,) P(|d angle| < R) per ZYX angle
    cloud : (m, 3) a subsample of position errors [m] kept for plots
    """

    n_samples: int
    stats: RunningStats
    position_tolerances: np.ndarray
    position_reliability: np.ndarray
    angle_tolerance: float
    angle_reliability: np.ndarray
    cloud: np.ndarray = field(repr=False)


def run_monte_carlo(budget: ErrorBudget, q: np.ndarray, n_samples: int, rng: np.random.Generator,
                    position_tolerances=(0.15e-3, 0.25e-3), angle_tolerance: float = 0.002,
                    chunk: int = CHUNK, keep_cloud: int = 20_000) -> MonteCarloResult:
    """Monte Carlo of the TCP pose error at joint values q (n_joints,) [rad, m].

    Parameters
    ----------
    budget : ErrorBudget
        The random error sources.
    n_samples : int
    rng : numpy Generator (the only source of randomness)
    position_tolerances : tolerances T on |dP| [m]
    angle_tolerance : tolerance R on each ZYX angle error [rad]
    """
    robot, error_model = budget.error_model.robot, budget.error_model
    nominal = tcp_poses(robot, q)
    tolerances = np.asarray(position_tolerances, dtype=float)
    stats = RunningStats()
    inside = np.zeros(tolerances.size)
    inside_angle = np.zeros(3)
    clouds = []
    done = 0
    while done < n_samples:
        n = min(chunk, n_samples - done)
        x = budget.sample(n, rng)
        err = pose_error(nominal, tcp_poses(robot, q, x, error_model))
        stats.add(np.column_stack([err.position, err.position_norm, err.euler_zyx]))
        inside += (err.position_norm[:, None] < tolerances[None, :]).sum(axis=0)
        inside_angle += (np.abs(err.euler_zyx) < angle_tolerance).sum(axis=0)
        if sum(len(c) for c in clouds) < keep_cloud:
            clouds.append(err.position[: keep_cloud - sum(len(c) for c in clouds)])
        done += n
    return MonteCarloResult(
        n_samples=n_samples,
        stats=stats,
        position_tolerances=tolerances,
        position_reliability=inside / n_samples,
        angle_tolerance=angle_tolerance,
        angle_reliability=inside_angle / n_samples,
        cloud=np.concatenate(clouds) if clouds else np.zeros((0, 3)),
    )
