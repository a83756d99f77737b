"""How sure the diagnosis is: parameter intervals, each effect's share and each step's gain
with their intervals, and how stable the selection is.

* :func:`parameter_table` -- every fitted parameter [SI] with its standard error (from the
  fit's Jacobian and residual: s^2 (J^T J)^-1), its 95 % interval, its physical range and
  whether the physics holds it on a bound (the data push beyond it).
* :class:`PoseBootstrap` -- one percentile bootstrap over the measured poses (every measured
  frame of a pose resampled with it, sessions as clusters where there are enough of them), drawn
  once per diagnosis: each held-out share, step gain and difference of two shares is read on the
  same replicates, so its interval holds its estimate and two shares compare paired.
* :func:`selection_frequency` -- the forward selection replayed on bootstrap resamples of
  the rows (each model's held-out errors as fitted; the resampling moves which effect wins
  each step and whether it passes the test): how often each effect is chosen.

Lengths in m inside; the returned dicts carry mm in ``_mm`` keys.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .bases import ordered
from .paired import row_squares

#: two-sided 95 % normal quantile
Z95 = 1.959963984540054


def parameter_table(result: dict, bases: dict, effects) -> dict:
    """Per effect: {"values", "std", "interval", "range", "fit_range", "pinned"} by parameter name [SI].

    ``result`` is a fit of :meth:`~tcr_accuracy.diagnosis.fitting.FitEngine.evaluate`. ``range``
    is the effect's physical range (its own physics), ``fit_range`` what the fit was held to;
    the interval is value +- 1.96 std cut to the fit range; ``pinned`` lists the parameters
    held on the fit range's bound, with the side.
    """
    theta = result["phi"] * result["scale"]
    std = result["phi_std"] * result["scale"]
    lower, upper = result["lower"] * result["scale"], result["upper"] * result["scale"]
    out, offset = {}, 0
    for e in effects:
        size = result["keep"][e].size
        block = slice(offset, offset + size)
        offset += size
        basis = bases[e]
        physical = {name: (float(lo), float(hi)) for name, lo, hi in zip(basis.names, basis.lower, basis.upper)}
        names = result["names"][block]
        rows = {"values": {}, "std": {}, "interval": {}, "range": {}, "fit_range": {}, "pinned": []}
        for name, v, s_, lo, hi, pinned in zip(names, theta[block], std[block], lower[block], upper[block],
                                              result["at_bound"][block]):
            rows["values"][name] = float(v)
            rows["std"][name] = float(s_)
            rows["interval"][name] = [float(max(v - Z95 * s_, lo)), float(min(v + Z95 * s_, hi))]
            rows["range"][name] = list(physical.get(name, (float(lo), float(hi))))
            rows["fit_range"][name] = [float(lo), float(hi)]
            if pinned and (np.isfinite(lo) or np.isfinite(hi)):
                rows["pinned"].append({"parameter": name,
                                       "bound": "lower" if abs(v - lo) <= abs(v - hi) else "upper"})
        out[e] = rows
    return out


def joint_function_bands(result: dict, bases: dict, effects, q: np.ndarray, n_points: int = 361) -> dict:
    """For effects that are functions of each joint's own angle (those with ``joint_basis``,
    e.g. ``cyclic``): effect -> joint -> {"angle_rad", "value_rad", "std_rad"} over the joint's
    measured range, the standard error from the fit's covariance (the penalised fit's
    posterior covariance, ``phi_cov``), or from the parameters' own standard errors when
    the model has no full covariance."""
    theta = result["phi"] * result["scale"]
    index = {name: i for i, name in enumerate(result["names"])}
    cov = result.get("phi_cov")
    cov = None if cov is None else cov * np.outer(result["scale"], result["scale"])
    std = result["phi_std"] * result["scale"]
    out = {}
    for e in effects:
        effect = bases[e].per_part[0].effect
        if not hasattr(effect, "joint_basis"):
            continue
        joints = {}
        for j, joint in enumerate(effect.robot.joint_names):
            angles = np.linspace(q[:, j].min(), q[:, j].max(), n_points)
            names, basis = effect.joint_basis(joint, angles)
            kept = [(c, index[n]) for c, n in enumerate(names) if n in index]
            if not kept:
                continue
            columns = np.array([c for c, _ in kept])
            rows = np.array([i for _, i in kept])
            b = basis[:, columns]
            value = b @ theta[rows]
            if cov is not None:
                spread = np.sqrt(np.maximum(np.einsum("mi,ij,mj->m", b, cov[np.ix_(rows, rows)], b), 0.0))
            else:
                spread = np.sqrt((b**2) @ np.where(np.isfinite(std[rows]), std[rows], 0.0) ** 2)
            joints[joint] = {"angle_rad": angles, "value_rad": value, "std_rad": spread}
        if joints:
            out[e] = joints
    return out


#: Replicates of the pose bootstrap (percentile intervals at 2.5 % and 97.5 % want some 2000).
BOOTSTRAP_REPLICATES = 2000
#: Fewest replicates: above ``BOOTSTRAP_CELLS / 1000`` clusters the replicates drop towards this, so
#: that the counts held (one byte per replicate and cluster) stay below ``BOOTSTRAP_CELLS``.
MIN_BOOTSTRAP_REPLICATES = 1000
BOOTSTRAP_CELLS = 40_000_000
#: Sessions are resampled as clusters from this many on. With fewer, a cluster bootstrap has too few
#: units to draw from (its intervals come out far too narrow or absurd), and the poses are resampled
#: within each session instead (strata): each replicate keeps every session's number of poses.
MIN_SESSION_CLUSTERS = 20


@dataclass(frozen=True)
class Interval:
    """An estimate [m] with its 95 % interval ``(low, high)`` [m], both read on the same rows."""

    value: float
    low: float
    high: float

    def __iter__(self):  # (value, low, high), as a tuple of three
        return iter((self.value, self.low, self.high))


@dataclass(frozen=True, eq=False)
class PoseBootstrap:
    """A percentile bootstrap over the measured poses, drawn once and read for every held-out figure.

    A figure here is a function of the per-row squared held-out errors of some models (each row: a
    pose, every measured frame on it added up, :func:`~.paired.row_squares`), e.g. a held-out RMS
    ``sqrt(mean(squares) / n_parts)`` or the difference of two. Each replicate draws the poses with
    replacement (a pose's measured frames go with it); where the rows carry enough sessions
    (:data:`MIN_SESSION_CLUSTERS`) whole sessions are drawn instead (their rows share a tracker
    frame's registration), and with fewer the poses are drawn within each session. The 95 % interval
    of a figure is the 2.5 % and 97.5 % quantiles of its value over the replicates, its point the
    value on the rows as measured: one computation for both, with the same replicates for every
    figure, so that differences of figures are paired. The fits are not redone per replicate: the
    held-out errors are those of the fits on all rows (their folds' refits), which the resampling
    reweighs.

    Build it with :meth:`draw`.

    Attributes
    ----------
    counts : ndarray of shape (B, C) of uint8
        How many times each cluster (a pose, or a session) is drawn in each replicate.
    cluster_of : ndarray of shape (N,) of int
        Each row's cluster.
    rows_in : ndarray of shape (C,)
        Rows per cluster.
    n_parts : int
        Measured frames per row: a row's squared error is the sum of its frames', an RMS is per point.
    method : str
        How the replicates were drawn, in words.
    """

    counts: np.ndarray
    cluster_of: np.ndarray
    rows_in: np.ndarray
    n_parts: int
    method: str

    @classmethod
    def draw(cls, n_rows: int, *, n_parts: int = 1, session_of=None, n_replicates: int | None = None,
             random_state=None) -> "PoseBootstrap":
        """Draw the replicates.

        Parameters
        ----------
        n_rows : int
            N, the poses (rows).
        n_parts : int, default=1
            Measured frames per row.
        session_of : ndarray of shape (N,) of int, default=None
            Each row's session; None: one session.
        n_replicates : int, default=None
            B; None: :data:`BOOTSTRAP_REPLICATES`, fewer for very many clusters (:data:`BOOTSTRAP_CELLS`).
        random_state : int, numpy.random.Generator or None
        """
        rng = random_state if isinstance(random_state, np.random.Generator) else np.random.default_rng(random_state)
        session_of = np.zeros(n_rows, dtype=int) if session_of is None else np.asarray(session_of)
        labels, session_of = np.unique(session_of, return_inverse=True)
        n_sessions = labels.size
        if n_sessions >= MIN_SESSION_CLUSTERS:
            cluster_of, strata = session_of, [np.arange(n_sessions)]
            method = f"whole sessions drawn with replacement ({n_sessions} sessions as clusters)"
        else:
            cluster_of = np.arange(n_rows)
            strata = [np.flatnonzero(session_of == s) for s in range(n_sessions)]
            method = "poses drawn with replacement" + (f" within each of the {n_sessions} sessions"
                                                        if n_sessions > 1 else "")
        n_clusters = int(cluster_of.max()) + 1 if n_rows else 0
        if n_replicates is None:
            n_replicates = int(np.clip(BOOTSTRAP_CELLS // max(n_clusters, 1), MIN_BOOTSTRAP_REPLICATES,
                                       BOOTSTRAP_REPLICATES))
        counts = np.zeros((n_replicates, n_clusters), dtype=np.uint8)
        chunk = max(1, int(4_000_000 // max(n_clusters, 1)))
        # a block's arrays are made in place, two at a time: its draws, their clusters and the clusters numbered
        # per replicate were each a new (b, clusters) array of int64, 32 MB at 10^4 poses, and four of them at
        # once were the diagnosis' peak of memory
        for first in range(0, n_replicates, chunk):
            b = min(chunk, n_replicates - first)
            block = None
            for members in strata:  # each stratum draws as many of its clusters as it has
                picked = rng.integers(0, members.size, size=(b, members.size))
                if not np.array_equal(members, np.arange(members.size)):  # one stratum of every cluster: itself
                    picked = members[picked]
                picked += (np.arange(b) * n_clusters)[:, None]  # replicate r's clusters at r * n_clusters + ...
                drawn = np.bincount(picked.ravel(), minlength=b * n_clusters)
                del picked
                if block is None:
                    block = drawn
                else:
                    block += drawn
                del drawn
            if block is None:
                block = np.zeros(b * n_clusters, dtype=np.int64)
            np.minimum(block, 255, out=block)  # a cluster drawn 255 times in a replicate: never
            counts[first:first + b] = block.reshape(b, n_clusters)
            del block
        rows_in = np.bincount(cluster_of, minlength=n_clusters).astype(float)
        return cls(counts=counts, cluster_of=cluster_of, rows_in=rows_in, n_parts=int(n_parts),
                   method=f"percentile bootstrap, {n_replicates} replicates: {method}, every measured frame of a "
                          "pose with it; the held-out errors of the fits on all rows reweighed, not refitted")

    @property
    def n_replicates(self) -> int:
        return self.counts.shape[0]

    def replicate_rms(self, squares) -> np.ndarray:
        """(B, m) the held-out RMS per measured point [m] in each replicate, for m models' per-row
        squared errors ((N, m), or (N,) for one: then (B,)). One pass over the replicates for all of
        them: read the models a stage compares together."""
        squares = np.asarray(squares, dtype=float)
        matrix = squares.reshape(squares.shape[0], -1)
        sums = np.stack([np.bincount(self.cluster_of, weights=matrix[:, k], minlength=self.rows_in.size)
                         for k in range(matrix.shape[1])], axis=1)
        out = np.empty((self.n_replicates, matrix.shape[1]))
        step = max(1, int(2_000_000 // max(self.rows_in.size, 1)))
        for first in range(0, self.n_replicates, step):
            block = self.counts[first:first + step].astype(float)
            out[first:first + step] = (block @ sums) / (block @ self.rows_in)[:, None]
        out = np.sqrt(np.maximum(out, 0.0) / self.n_parts)
        return out if squares.ndim > 1 else out[:, 0]

    def rms(self, squares: np.ndarray) -> float:
        """The held-out RMS per measured point [m] of rows' squared errors (N,) [m^2]."""
        return math.sqrt(float(np.mean(squares)) / self.n_parts)

    def read(self, squares: dict) -> "BootstrapTable":
        """The models' held-out RMS on the rows and in every replicate, for comparing them:
        ``squares``: name -> per-row squared held-out errors (N,) (:func:`~.paired.row_squares`)."""
        names = list(squares)
        matrix = np.stack([np.asarray(squares[k], dtype=float) for k in names], axis=1)
        replicates = self.replicate_rms(matrix)
        return BootstrapTable({k: self.rms(squares[k]) for k in names},
                              {k: replicates[:, i] for i, k in enumerate(names)})

    def difference(self, before: np.ndarray, after: np.ndarray, level: float = 0.95) -> Interval:
        """How much higher the held-out RMS of ``before`` is than that of ``after`` [m], with its
        percentile interval at ``level``: per-row squared held-out errors (N,) of two models on the
        same rows (:func:`~.paired.row_squares`)."""
        return self.read({0: before, 1: after}).difference(0, 1, level)


@dataclass(frozen=True)
class BootstrapTable:
    """Models' held-out RMS [m] on the measured rows (``point``) and in each replicate of one
    :class:`PoseBootstrap` (``replicates``: (B,) each), by name."""

    point: dict
    replicates: dict

    def difference(self, before, after, level: float = 0.95) -> Interval:
        """How much higher the held-out RMS of model ``before`` is than that of ``after`` [m], with
        its percentile interval at ``level`` (paired: the same replicates for both)."""
        spread = self.replicates[before] - self.replicates[after]
        low, high = np.quantile(spread, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
        return Interval(float(self.point[before] - self.point[after]), float(low), float(high))


def bootstrap_for(engine, random_state=None) -> PoseBootstrap:
    """The pose bootstrap of a fit engine's rows (its measured frames, the first frame's sessions)."""
    part = engine.parts[0]
    return PoseBootstrap.draw(engine.n_rows, n_parts=len(engine.parts), session_of=part.context.session,
                              random_state=random_state)


def selection_frequency(engine, testable: list, selection_z: float, min_relative_gain: float,
                        n_replays: int, rng: np.random.Generator, say=lambda message: None, late=()) -> dict:
    """Forward selection replayed on ``n_replays`` bootstrap resamples of the rows: each
    step's candidates compared on the resampled rows' held-out errors (paired z and relative
    gain as in the diagnosis); a model not fitted yet is fitted once and cached. Effects in
    ``late`` (tried last in the diagnosis) are offered once the others are settled. Returns
    {effect: share of the replays that chose it} for every testable effect, and the share of
    replays that ended on each set (``sets``)."""
    n = engine.n_rows
    counts = {e: 0 for e in testable}
    sets: dict = {}
    for replay in range(n_replays):
        if replay % 10 == 0:
            say(f"selection stability: replay {replay + 1} of {n_replays}")
        rows = rng.integers(0, n, n)
        current = ["frames"]
        for pool in ([e for e in testable if e not in late], [e for e in testable if e in late]):
            _replay_forward(engine, current, pool, rows, selection_z, min_relative_gain)
        for e in current[1:]:
            counts[e] += 1
        key = ", ".join(ordered(current))
        sets[key] = sets.get(key, 0) + 1
    return {"frequency": {e: c / n_replays for e, c in counts.items()},
            "sets": {k: v / n_replays for k, v in sorted(sets.items(), key=lambda kv: -kv[1])},
            "n_replays": n_replays,
            "method": "forward selection replayed on bootstrap resamples of the rows (each model's out-of-fold "
                      "errors as fitted once; the resampling changes which effect wins each step and whether "
                      "it passes the paired test)"}


def _replay_forward(engine, current: list, pool: list, rows: np.ndarray, selection_z: float,
                    min_relative_gain: float) -> None:
    """One forward selection on resampled rows, from ``current`` (extended in place)."""
    pool = list(pool)
    while pool:
        prev = engine.evaluate(ordered(current))["heldout_squares"]
        prev_sq = row_squares(prev)[rows]
        trials = {e: row_squares(engine.evaluate(ordered(current + [e]))["heldout_squares"])[rows] for e in pool}
        best = min(trials, key=lambda e: trials[e].mean())
        d = prev_sq - trials[best]
        sd = d.std(ddof=1)
        z = math.inf if sd == 0 and d.mean() > 0 else (d.mean() / (sd / math.sqrt(d.size)) if sd > 0 else 0.0)
        if not (z > selection_z and math.sqrt(trials[best].mean()) < math.sqrt(prev_sq.mean())
                * (1.0 - min_relative_gain)):
            return
        current.append(best)
        pool.remove(best)


def implausibility(result: dict, bases: dict, effect: str) -> float:
    """How far an effect's fitted parameters in a fit lie from what its own physics makes typical:
    the RMS over its parameters of value / physical bound (the bound on the value's side, or the
    other side's where its physics allows only one sign), 0 for an unbounded effect. Below 1: the
    textbook sizes; above: sizes only another mechanism (or a stand-in role) explains."""
    basis = bases[effect]
    theta = result["phi"] * result["scale"]
    offset = 0
    for e in result["effects"]:
        size = result["keep"][e].size
        if e == effect:
            kept = result["keep"][e]
            values = theta[offset:offset + size]
            lower, upper = basis.lower[kept], basis.upper[kept]
            bound = np.where(values >= 0, upper, -lower)
            bound = np.where(bound > 0, bound, np.maximum(upper, -lower))
            finite = np.isfinite(bound) & (bound > 0)
            if not finite.any():
                return 0.0
            return float(np.sqrt(np.mean((values[finite] / bound[finite]) ** 2)))
        offset += size
    return 0.0
