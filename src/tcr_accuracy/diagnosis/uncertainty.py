"""How sure the diagnosis is: parameter intervals, each effect's share and each step's gain
with their intervals, and how stable the selection is.

* :func:`parameter_table` -- every fitted parameter [SI] with its standard error (from the
  fit's Jacobian and residual: s^2 (J^T J)^-1), its 95 % interval, its physical range and
  whether the physics holds it on a bound (the data push beyond it).
* :func:`difference_interval` -- a held-out RMS difference between two models on the same
  rows, with its 95 % interval from the paired per-row squared errors.
* :func:`selection_frequency` -- the forward selection replayed on bootstrap resamples of
  the rows (each model's held-out errors as fitted; the resampling moves which effect wins
  each step and whether it passes the test): how often each effect is chosen.

Lengths in m inside; the returned dicts carry mm in ``_mm`` keys.
"""

from __future__ import annotations

import math

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


def difference_interval(before: np.ndarray, after: np.ndarray) -> tuple[float, float, float]:
    """How much lower the held-out RMS of ``after`` is than that of ``before`` [m], with the
    95 % interval: the mean cut in per-row squared errors and its standard error (paired,
    rows independent), turned into RMS. before, after: (N, 3) or (n_parts, N, 3)."""
    a, b = row_squares(before), row_squares(after)
    n = a.size
    d = a - b
    se = float(d.std(ddof=1) / math.sqrt(n)) if n > 1 else 0.0
    mean_a = float(a.mean())

    def gain(cut):  # RMS before minus RMS after, for a cut in the mean squared error
        return math.sqrt(mean_a) - math.sqrt(max(mean_a - cut, 0.0))

    cut = float(d.mean())
    return gain(cut), gain(cut - Z95 * se), gain(cut + Z95 * se)


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
