"""Monte Carlo accuracy of the TCP under random error sources, and its reliability.

Any *sampler* works: an object with ``error_model`` (an
:class:`~tcr_accuracy.model.errors.ErrorModel`), ``name`` and ``sample(n, rng) -> (n,
n_params)`` error vectors, such as an :class:`~tcr_accuracy.model.errors.ErrorBudget` or a
:class:`~tcr_accuracy.model.clearance.ClearanceModel`.

The samples are processed in chunks of a fixed size (memory does not grow with the
sample count). Chunk ``k`` draws its samples from its own generator seeded by
``SeedSequence(seed).spawn(n_chunks)[k]``, and the per-chunk summaries are merged in
chunk order. So the result depends only on (seed, n_samples, chunk), never on how
many processes or Dask workers ran the chunks: a run on a cluster is bit-for-bit the
single-process run.

Statistic columns (:data:`STAT_COLUMNS`): ``dx, dy, dz`` position error in the base
frame [m], ``norm`` = |dP| [m], the ZYX Euler angle errors [rad], and ``dp`` the
signed radial error [m] (see :func:`radial_error`).

About the seed's "Delta p" row (Tables 3 and 5): it cannot be |dP| (its minimum is
negative), nor any fixed linear combination of dx, dy, dz with unit-norm weights
(Table 3's mean, 0.0112 mm, is 14 standard errors from zero while the component
means are below 3e-4 mm, so such a combination could reach at most 4.6e-4 mm), nor
|dP| minus its mean (Table 3's tails are nearly symmetric, -3.5 / +4.2 std, where a
centred norm gives about -1.9 / +5.3). We report ``dp`` as the signed radial error,
which has the seed row's sign behaviour and is defined independently of the frame.

One concept, the chunked Monte Carlo run and its merged statistics (the chunk loop, the Dask path
and the reliability read from the same summaries), and so one module above 500 lines.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from ..model.errors import ErrorBudget, ErrorModel
from ..model.kinematics import euler_zyx, euler_zyx_entries, tcp_chain_soa, tcp_poses
from ..model.scratch import ScratchArrays, scratch, scratch_like
from ..random_state import fill_standard_normal, renamed_keyword

#: Default chunk of samples processed at once (cache-friendly; part of the seeding contract).
CHUNK = 20_000

#: Columns of the statistics: position errors [m], ZYX Euler angle errors [rad], signed radial error [m].
STAT_COLUMNS = ("dx", "dy", "dz", "norm", "d_alpha_z", "d_beta_y", "d_gamma_x", "dp")


class Sampler(Protocol):
    """What the engine needs from a source of random error vectors."""

    error_model: ErrorModel
    name: str

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:  # (n, n_params)
        ...


@dataclass
class RunningStats:
    """Count, mean, sum of squared deviations (M2), min and max, column by column.

    Merging uses Chan et al.'s pairwise update, which stays accurate when the mean is
    large against the spread (unlike sum / sum of squares).
    """

    count: int = 0
    mean_: np.ndarray | None = None
    m2: np.ndarray | None = None
    minimum: np.ndarray | None = None
    maximum: np.ndarray | None = None

    @classmethod
    def of(cls, values: np.ndarray) -> "RunningStats":
        """Statistics of one (n, k) block."""
        values = np.asarray(values, dtype=float)
        mean = values.mean(axis=0)
        return cls(count=values.shape[0], mean_=mean, m2=((values - mean) ** 2).sum(axis=0),
                   minimum=values.min(axis=0), maximum=values.max(axis=0))

    def add(self, values: np.ndarray) -> None:
        """Fold in an (n, k) block of values."""
        self.merge(RunningStats.of(values))

    def merge(self, other: "RunningStats") -> None:
        if other.count == 0:
            return
        if self.count == 0:
            self.count, self.mean_, self.m2 = other.count, other.mean_.copy(), other.m2.copy()
            self.minimum, self.maximum = other.minimum.copy(), other.maximum.copy()
            return
        n = self.count + other.count
        delta = other.mean_ - self.mean_
        self.mean_ = self.mean_ + delta * (other.count / n)
        self.m2 = self.m2 + other.m2 + delta**2 * (self.count * other.count / n)
        self.count = n
        self.minimum = np.minimum(self.minimum, other.minimum)
        self.maximum = np.maximum(self.maximum, other.maximum)

    @property
    def mean(self) -> np.ndarray:
        return self.mean_

    @property
    def std(self) -> np.ndarray:
        """Sample standard deviation (ddof = 1)."""
        return np.sqrt(self.m2 / max(self.count - 1, 1))


@dataclass
class ChunkSummary:
    """What one chunk contributes: statistics, counts inside the tolerances, a bit of cloud."""

    index: int
    stats: RunningStats
    inside_position: np.ndarray  # (n_tol,) counts of |dP| < T
    inside_angle: np.ndarray  # (3,) counts of |d angle| < R
    cloud: np.ndarray  # (m, 3) first position errors [m]


@dataclass
class MonteCarloResult:
    """Statistics of the TCP pose error over the samples.

    Attributes
    ----------
    n_samples : int
    stats : RunningStats over :data:`STAT_COLUMNS` (SI units)
    position_tolerances : (k,) tolerances T [m]
    inside_position : (k,) number of samples with |dP| < T
    angle_tolerance : R [rad]
    inside_angle : (3,) number of samples with |d angle| < R, per ZYX angle
    cloud : (m, 3) the first m position errors [m], for plots
    nominal_position : (3,) nominal TCP position [m]
    seed : the entropy of the root SeedSequence
    chunk : chunk size used
    """

    n_samples: int
    stats: RunningStats
    position_tolerances: np.ndarray
    inside_position: np.ndarray
    angle_tolerance: float
    inside_angle: np.ndarray
    cloud: np.ndarray = field(repr=False)
    nominal_position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    seed: object = None
    chunk: int = CHUNK

    @property
    def position_reliability(self) -> np.ndarray:
        """(k,) P(|dP| < T), Eq. (25) of the seed."""
        return self.inside_position / self.n_samples

    @property
    def angle_reliability(self) -> np.ndarray:
        """(3,) P(|d angle_i| < R) per ZYX angle."""
        return self.inside_angle / self.n_samples

    def column(self, name: str) -> int:
        return STAT_COLUMNS.index(name)

    def __repr__(self) -> str:
        norm = self.column("norm")
        inside = ", ".join(f"P(|dP| < {t * 1e3:g} mm) = {p:.4f}"
                           for t, p in zip(self.position_tolerances, self.position_reliability))
        return (f"MonteCarloResult({self.n_samples} samples, |dP| mean {self.stats.mean[norm] * 1e3:.4g} mm, "
                f"std {self.stats.std[norm] * 1e3:.4g} mm, max {self.stats.maximum[norm] * 1e3:.4g} mm, {inside})")


# ---------------------------------------------------------------------------------------
# Per-sample error metrics
# ---------------------------------------------------------------------------------------
def radial_error(nominal_position: np.ndarray, actual_position: np.ndarray) -> np.ndarray:
    """Signed radial error ``|P_actual| - |P_nominal|`` (N,) [m]: reach gained (+) or lost (-).

    The change of the TCP's distance from the base origin. To first order it is the
    projection of dP on the unit vector from the base origin to the nominal TCP, so
    unlike |dP| it has a sign, a mean and a minimum below zero.
    """
    return np.linalg.norm(actual_position, axis=1) - np.linalg.norm(nominal_position)


# ---------------------------------------------------------------------------------------
# Seeding and chunking
# ---------------------------------------------------------------------------------------
def root_seed_sequence(seed) -> np.random.SeedSequence:
    """A SeedSequence from an int, a SeedSequence, a Generator (drawn from it) or None (0)."""
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, np.random.Generator):
        return np.random.SeedSequence(seed.integers(0, 2**63, size=4).tolist())
    return np.random.SeedSequence(0 if seed is None else seed)


def chunk_plan(n_samples: int, chunk: int) -> list[int]:
    """Sizes of the chunks: all ``chunk`` except a shorter last one."""
    full, rest = divmod(int(n_samples), int(chunk))
    return [chunk] * full + ([rest] if rest else [])


@dataclass
class ChunkTask:
    """Everything a worker needs to run one chunk (picklable).

    Each thread that runs chunks of the task keeps its own :class:`ScratchArrays` on it
    (:meth:`scratch_arrays`), so a process that runs many chunks (this one, or a Dask
    worker holding the scattered task) reuses the same warm memory; the pools are not
    pickled.
    """

    sampler: object
    q: np.ndarray
    nominal_position: np.ndarray
    nominal_euler: np.ndarray
    tolerances: np.ndarray
    angle_tolerance: float
    keep_cloud: int
    chunk: int
    _threads: threading.local = field(default_factory=threading.local, init=False, repr=False, compare=False)

    def scratch_arrays(self) -> ScratchArrays:
        """The calling thread's scratch pool for this task's chunks."""
        pool = getattr(self._threads, "pool", None)
        if pool is None:
            pool = self._threads.pool = ScratchArrays()
        return pool

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k != "_threads"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state, _threads=threading.local())


def sample_rows(sampler, n: int, rng: np.random.Generator) -> list:
    """n error vectors as a list of n_params rows: (n,) arrays, or 0.0 for unused parameters.

    For an :class:`~tcr_accuracy.model.errors.ErrorBudget` the normal sources are drawn
    together into one (n_normal, n) array by
    :func:`~tcr_accuracy.random_state.fill_standard_normal` (then the other sources in
    order, with their own ``sample``), and each parameter row is built only from the
    sources that touch it (the budget matrix is sparse: a link length or a drive error
    moves one or a few parameters), scaling a source's draws in place when it moves one
    parameter only, so no (n, n_params) array is formed and transposed. The values
    follow the budget's distributions exactly; the random stream is this function's own
    (it is not ``budget.sample``'s). Any other sampler: ``sampler.sample(n, rng)``,
    transposed.
    """
    if isinstance(sampler, ErrorBudget):
        matrix = sampler.matrix
        sources = sampler.sources
        values: list = [None] * len(sources)
        normal = [i for i, src in enumerate(sources) if src.distribution == "normal"]
        if normal:
            z = scratch((len(normal), n))
            z = fill_standard_normal(rng, np.empty((len(normal), n)) if z is None else z,
                                     scratch((2, (len(normal) * n + 1) // 2), np.float32))
            for row, i in enumerate(normal):
                values[i] = z[row]
        for i, src in enumerate(sources):
            if values[i] is None:
                values[i] = src.sample(n, rng)
        moves = np.count_nonzero(matrix, axis=0)  # parameters each source moves
        rows: list = [0.0] * matrix.shape[0]
        for k in np.flatnonzero(np.any(matrix != 0.0, axis=1)):
            row, offset = None, 0.0
            for i in np.flatnonzero(matrix[k]):
                src, weight = sources[i], matrix[k, i]
                scale = weight * src.std if src.distribution == "normal" else weight
                if src.distribution == "normal":  # value = mean + std z
                    offset += weight * src.mean
                if row is None and moves[i] == 1:  # these draws serve this row only
                    row = values[i]
                    row *= scale
                elif row is None:
                    row = np.multiply(values[i], scale, out=scratch_like(values[i]))
                else:
                    row += values[i] * scale
            if offset != 0.0:
                row += offset
            rows[k] = row
        return rows
    x = np.asarray(sampler.sample(n, rng), dtype=float)
    return list(np.ascontiguousarray(x.T))


def error_rows(nominal_position: np.ndarray, nominal_euler: np.ndarray, rot: np.ndarray,
               pos: np.ndarray) -> np.ndarray:
    """(8, N) values of :data:`STAT_COLUMNS` from the engine's (9, N) rotations and (3, N) positions.

    Built row by row in place (rows not yet filled serve as scratch), so the only new
    array is the result.
    """
    shape = (len(STAT_COLUMNS), pos.shape[1])
    out = scratch(shape)
    out = np.empty(shape) if out is None else out
    free_row = out[4]  # free until the Euler angles are written
    _norm_into(np.subtract(pos, nominal_position[:, None], out=out[:3]), out[3], free_row)
    _norm_into(pos, out[7], free_row)
    out[7] -= np.linalg.norm(nominal_position)
    angles = euler_zyx_entries(rot[0], rot[3], rot[6], rot[7], rot[8], out=out[4:7])  # on the rows of R
    angles -= nominal_euler[:, None]
    if angles.min() < -np.pi or angles.max() >= np.pi:  # wrap to [-pi, pi) only when needed
        angles += np.pi
        np.mod(angles, 2 * np.pi, out=angles)
        angles -= np.pi
    return out


def _norm_into(vectors: np.ndarray, out: np.ndarray, work: np.ndarray) -> np.ndarray:
    """Euclidean norms of (3, N) column vectors into out (N,), using work (N,)."""
    np.multiply(vectors[0], vectors[0], out=out)
    for component in vectors[1:]:
        np.multiply(component, component, out=work)
        out += work
    return np.sqrt(out, out=out)


def run_chunk(task: ChunkTask, index: int, size: int, seed: np.random.SeedSequence) -> ChunkSummary:
    """Sample and evaluate one chunk; a pure function of its arguments."""
    with task.scratch_arrays().active():
        return _run_chunk(task, index, size, seed)


def _run_chunk(task: ChunkTask, index: int, size: int, seed: np.random.SeedSequence) -> ChunkSummary:
    rng = np.random.default_rng(seed)
    sampler = task.sampler
    rows = sample_rows(sampler, size, rng)
    rot, pos = tcp_chain_soa(sampler.error_model.robot, task.q, rows, sampler.error_model)
    del rows
    values = error_rows(task.nominal_position, task.nominal_euler, rot, pos)
    del rot, pos
    keep = max(0, min(size, task.keep_cloud - index * task.chunk))
    cloud = values[:3, :keep].T.copy()
    inside_position = np.array([np.count_nonzero(values[3] < t) for t in task.tolerances], dtype=np.int64)
    magnitude = np.abs(values[4:7], out=scratch((3, size)))
    inside_angle = np.array([np.count_nonzero(row < task.angle_tolerance) for row in magnitude], dtype=np.int64)
    del magnitude
    minimum, maximum = values.min(axis=1), values.max(axis=1)
    mean = values.mean(axis=1)
    values -= mean[:, None]  # centred in place: the values are not needed any more
    stats = RunningStats(count=size, mean_=mean, m2=np.einsum("kn,kn->k", values, values),
                         minimum=minimum, maximum=maximum)
    return ChunkSummary(index=index, stats=stats, inside_position=inside_position, inside_angle=inside_angle,
                        cloud=cloud)


@renamed_keyword("sampler", "budget")
@renamed_keyword("rng", "random_state")
def run_monte_carlo(budget: ErrorBudget | Sampler, q: np.ndarray, n_samples: int, random_state=None, *,
                    position_tolerances=(0.15e-3, 0.25e-3), angle_tolerance: float = 0.002,
                    chunk: int = CHUNK, keep_cloud: int = 20_000,
                    progress: Callable[[int], None] | None = None, client=None,
                    max_pending: int | None = None) -> MonteCarloResult:
    """Monte Carlo of the TCP pose error at fixed joint values q (n_joints,) [rad, m].

    Parameters
    ----------
    budget : ErrorBudget or Sampler
        Where the random error vectors come from: an
        :class:`~tcr_accuracy.model.errors.ErrorBudget` (``tcr.seed_budget``, a budget
        file), or any other :class:`Sampler` (e.g. a
        :class:`~tcr_accuracy.model.clearance.ClearanceModel`): an object with
        ``error_model``, ``name`` and ``sample(n, rng) -> (n, n_params)``. Formerly
        ``sampler``.
    q : array-like of shape (n_joints,)
        Joint values [rad, m].
    n_samples : int
        Number of samples (>= 1).
    random_state : int, numpy.random.SeedSequence, numpy.random.Generator or None, default=None
        Root of the per-chunk seeds (a Generator is drawn from once; None: 0). Formerly
        ``rng``.
    position_tolerances : sequence of float, default=(0.15e-3, 0.25e-3)
        Tolerances T on |dP| [m].
    angle_tolerance : float, default=0.002
        Tolerance R on each ZYX angle error [rad].
    chunk : int, default=20000
        Samples per chunk. Part of the random stream: the same (random_state, chunk) gives
        the same samples.
    keep_cloud : int, default=20000
        Number of position errors kept for plots.
    progress : callable, default=None
        Called with the number of samples finished after each chunk.
    client : dask.distributed.Client, default=None
        Run the chunks as tasks on this cluster; results are merged in chunk order.
    max_pending : int, default=None
        Most chunks in flight on the cluster (bounds memory), default 4 per worker.

    Returns
    -------
    MonteCarloResult
        Statistics of the pose error (SI) and the counts inside the tolerances.

    Examples
    --------
    >>> import numpy as np, tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> budget = tcr.seed_budget(robot, "table1")
    >>> mc = tcr.run_monte_carlo(budget, np.radians([0, -90, 90, 0, 90, 0]), 2_000, random_state=0)
    >>> mc.n_samples
    2000
    """
    sampler = budget
    if n_samples < 1:
        raise ValueError("n_samples must be >= 1")
    q = np.asarray(q, dtype=float)
    robot = sampler.error_model.robot
    nominal = tcp_poses(robot, q)
    tolerances = np.atleast_1d(np.asarray(position_tolerances, dtype=float))
    task = ChunkTask(sampler=sampler, q=q, nominal_position=nominal.position[0],
                     nominal_euler=euler_zyx(nominal.rotation)[0], tolerances=tolerances,
                     angle_tolerance=float(angle_tolerance), keep_cloud=int(keep_cloud), chunk=int(chunk))
    root = root_seed_sequence(random_state)
    sizes = chunk_plan(n_samples, chunk)
    seeds = root.spawn(len(sizes))
    merged = _Merger(len(tolerances))
    if client is None:
        for k, (size, seed) in enumerate(zip(sizes, seeds)):
            merged.add(run_chunk(task, k, size, seed))
            if progress is not None:
                progress(size)
    else:
        _run_on_cluster(client, task, sizes, seeds, merged, progress, max_pending)
    return MonteCarloResult(
        n_samples=merged.stats.count, stats=merged.stats, position_tolerances=tolerances,
        inside_position=merged.inside_position, angle_tolerance=float(angle_tolerance),
        inside_angle=merged.inside_angle,
        cloud=np.concatenate(merged.clouds) if merged.clouds else np.zeros((0, 3)),
        nominal_position=nominal.position[0], seed=root.entropy, chunk=int(chunk),
    )


def drawn_error_vectors(sampler, n_samples: int, random_state=None, *, chunk: int = CHUNK,
                        count: int | None = None) -> np.ndarray:
    """The error vectors :func:`run_monte_carlo` draws for its first ``count`` samples.

    The run's random stream is fixed by (random_state, n_samples, chunk): chunk ``k`` draws from
    ``SeedSequence(random_state).spawn(n_chunks)[k]`` through :func:`sample_rows`. Drawn again
    here, so that a view or a plot shows the very samples the run's statistics count.

    Parameters
    ----------
    sampler : ErrorBudget or Sampler
    n_samples : int
        The run's number of samples.
    random_state, chunk
        As given to :func:`run_monte_carlo`.
    count : int, default=None
        How many of the first samples (default: all ``n_samples``).

    Returns
    -------
    ndarray of shape (count, n_params)
        Error vectors in the layout of ``sampler.error_model``.
    """
    count = int(n_samples if count is None else min(count, n_samples))
    sizes = chunk_plan(n_samples, chunk)
    seeds = root_seed_sequence(random_state).spawn(len(sizes))
    n_params = sampler.error_model.size
    out, done = np.zeros((count, n_params)), 0
    for size, seed in zip(sizes, seeds):
        if done >= count:
            break
        rows = sample_rows(sampler, size, np.random.default_rng(seed))
        take = min(size, count - done)
        for k, row in enumerate(rows):
            out[done:done + take, k] = row[:take] if isinstance(row, np.ndarray) else row
        done += take
    return out


class _Merger:
    """Folds chunk summaries in chunk order (the order fixes the floating-point sums)."""

    def __init__(self, n_tol: int):
        self.stats = RunningStats()
        self.inside_position = np.zeros(n_tol, dtype=np.int64)
        self.inside_angle = np.zeros(3, dtype=np.int64)
        self.clouds: list[np.ndarray] = []
        self.next_index = 0
        self.waiting: dict[int, ChunkSummary] = {}

    def add(self, summary: ChunkSummary) -> None:
        self.waiting[summary.index] = summary
        while self.next_index in self.waiting:
            s = self.waiting.pop(self.next_index)
            self.stats.merge(s.stats)
            self.inside_position += s.inside_position
            self.inside_angle += s.inside_angle
            if len(s.cloud):
                self.clouds.append(s.cloud)
            self.next_index += 1


def _run_on_cluster(client, task, sizes, seeds, merged, progress, max_pending) -> None:
    """Submit chunks to a Dask cluster with a bounded number in flight; merge in order."""
    from distributed import as_completed

    n_workers = max(1, len(client.scheduler_info().get("workers", {})))
    limit = max_pending or 4 * n_workers
    [task_future] = client.scatter([task], broadcast=True)
    todo = iter(range(len(sizes)))
    pool = as_completed()
    size_of = {}

    def submit_next() -> bool:
        k = next(todo, None)
        if k is None:
            return False
        future = client.submit(run_chunk, task_future, k, sizes[k], seeds[k], pure=False)
        size_of[future.key] = sizes[k]
        pool.add(future)
        return True

    for _ in range(limit):
        if not submit_next():
            break
    for future in pool:
        summary = future.result()
        merged.add(summary)
        if progress is not None:
            progress(size_of.pop(future.key))
        future.release()
        submit_next()
