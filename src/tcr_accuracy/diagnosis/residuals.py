"""What is left after a fit: where a residual lies and how noisy the measurements are.

The diagnosis breaks the gap down over the workspace and the conditions
(:func:`where_analysis`) and estimates the measurement scatter when the instrument's is not
given (:func:`noise_from_repeats`, :func:`noise_from_residual`); whether the final residual
still has structure is :mod:`tcr_accuracy.diagnosis.structure`'s. Lengths in m inside, mm
in the returned dicts' ``_mm`` keys.
"""

from __future__ import annotations

import math
import numpy as np

from ..exceptions import InputError
from ..frames.noise import NoiseEstimate
from ..model.robot import RobotModel
from ..analysis.semivariogram import (
    EmpiricalSemivariogram,
    empirical_semivariogram,
    fit_gaussian_variogram,
    nearest_neighbours,
    per_joint_semivariograms,
    standardize,
)


# ---------------------------------------------------------------------------------------
# Where the gap lies
# ---------------------------------------------------------------------------------------
def _binned(values: np.ndarray, residual: np.ndarray, n_bins: int = 5) -> dict:
    """Quantile bins of values (N,): count, mean residual vector and RMS norm per bin [mm]."""
    finite = np.isfinite(values)
    levels = np.unique(values[finite])
    if levels.size <= n_bins:  # a few distinct values (payload on/off): one bin each
        if levels.size < 2:
            return {"bins": [], "spread_mm": 0.0}
        edges = None
        which = np.searchsorted(levels, values)
    else:
        edges = np.unique(np.quantile(values[finite], np.linspace(0, 1, n_bins + 1)))
        which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, edges.size - 2)
    bins = []
    n_out = levels.size if edges is None else edges.size - 1
    for b in range(n_out):
        sel = which == b
        if not sel.any():
            continue
        r = residual[sel]
        low, high = (levels[b], levels[b]) if edges is None else (edges[b], edges[b + 1])
        bins.append({"low": float(low), "high": float(high), "count": int(sel.sum()),
                     "mean_mm": (r.mean(axis=0) * 1e3).tolist(),
                     "rms_mm": float(np.sqrt(np.mean(np.sum(r**2, axis=1))) * 1e3)})
    means = np.array([b["mean_mm"] for b in bins])
    spread = float(np.linalg.norm(means.max(axis=0) - means.min(axis=0))) if len(bins) > 1 else 0.0
    return {"bins": bins, "spread_mm": spread}


def _correlations(values: np.ndarray, residual: np.ndarray) -> list:
    out = []
    for c in range(3):
        if np.std(values) == 0 or np.std(residual[:, c]) == 0:
            out.append(0.0)
        else:
            out.append(float(np.corrcoef(values, residual[:, c])[0, 1]))
    return out


def where_analysis(robot: RobotModel, q: np.ndarray, nominal: np.ndarray, residual: np.ndarray,
                   tau: np.ndarray, context: dict, n_bins: int = 5, rng=None, knn_shares=None):
    """Breakdown of the residual (N, 3) [m]; returns (JSON-able dict, semivariograms).

    ``knn_shares``: optional callable, residual (N, 3) -> {joint indices (tuple): share of its variance the
    k = 10 nearest neighbours along those joints (standardised) predict out of sample}, for every moving
    joint and pair (the structure test's :meth:`~tcr_accuracy.diagnosis.structure.StructureDetector.shares`,
    whose neighbours are found once for the diagnosis); without it the neighbours are found here."""
    norm = np.linalg.norm(residual, axis=1)
    where: dict = {}
    where["per_axis"] = {ax: {"mean_mm": float(residual[:, c].mean() * 1e3),
                              "rms_mm": float(np.sqrt(np.mean(residual[:, c] ** 2)) * 1e3),
                              "max_abs_mm": float(np.abs(residual[:, c]).max() * 1e3)}
                         for c, ax in enumerate("xyz")}
    centre = np.median(nominal, axis=0)
    octant = ((nominal - centre) > 0).astype(int) @ np.array([4, 2, 1])
    regions = []
    for o in range(8):
        sel = octant == o
        if sel.any():
            label = "".join(("+" if (o >> (2 - c)) & 1 else "-") + "xyz"[c] for c in range(3))
            regions.append({"region": label, "count": int(sel.sum()),
                            "mean_mm": float(norm[sel].mean() * 1e3),
                            "rms_mm": float(np.sqrt(np.mean(norm[sel] ** 2)) * 1e3)})
    where["octants"] = {"centre_m": centre.tolist(), "regions": regions}
    where["radius"] = _binned(np.hypot(nominal[:, 0], nominal[:, 1]), residual, n_bins)
    where["height"] = _binned(nominal[:, 2], residual, n_bins)
    joints = {}
    for j, name in enumerate(robot.joint_names):
        joints[name] = {"unit": "rad" if robot.joint_kinds[j] == "revolute" else "m",
                        "correlation_xyz": _correlations(q[:, j], residual), **_binned(q[:, j], residual, n_bins)}
    where["joints"] = joints
    loaded = np.ptp(tau, axis=0) > 1e-6 * max(float(np.abs(tau).max()), 1e-300)
    where["gravity_torque"] = {name: ({"correlation_xyz": _correlations(tau[:, j], residual),
                                       **_binned(tau[:, j], residual, n_bins)} if loaded[j]
                                      else {"loaded": False})
                               for j, name in enumerate(robot.joint_names)}
    for key in ("payload_kg", "temperature_c"):
        if key in context and np.std(context[key]) > 0:
            where[key] = {"correlation_xyz": _correlations(context[key], residual),
                          **_binned(context[key], residual, n_bins)}
    if "direction" in context:
        direction = {}
        for j, name in enumerate(robot.joint_names):
            d = context["direction"][:, j]
            plus, minus = d > 0, d < 0
            if plus.any() and minus.any():
                diff = residual[plus].mean(axis=0) - residual[minus].mean(axis=0)
                direction[name] = {"count_plus": int(plus.sum()), "count_minus": int(minus.sum()),
                                   "mean_plus_minus_minus_mm": (diff * 1e3).tolist(),
                                   "difference_norm_mm": float(np.linalg.norm(diff) * 1e3)}
        where["approach_direction"] = direction
    # along which joints does the error vary? Per-joint semivariograms (standardised:
    # 1 = no similarity) at short lag, and the share of the residual variance that the
    # k nearest neighbours along that joint alone predict (out of sample: self excluded)
    semis = per_joint_semivariograms(q, residual, n_bins=12, rng=rng)
    centred = residual - residual.mean(axis=0)
    total = float(np.sum(centred**2)) or 1.0
    along = {}
    known = knn_shares(residual) if knn_shares is not None else {}

    def knn_share(points):
        """The residual's variance share its k = 10 nearest neighbours among ``points`` predict."""
        idx = nearest_neighbours(points, min(10, q.shape[0] - 1))
        return 1.0 - float(np.sum((centred - centred[idx].mean(axis=1)) ** 2)) / total

    for j, name in enumerate(robot.joint_names):
        if np.ptp(q[:, j]) == 0:  # a joint held still (np.std of equal values is their mean's rounding, not 0)
            continue
        s = semis[j]
        short = s.lags <= np.quantile(s.lags, 0.25)
        gamma_short = (s.semivariance[short] * s.counts[short, None]).sum(axis=0) / s.counts[short].sum()
        share = known.get((j,))
        if share is None:
            share = knn_share(q[:, [j]])
        along[name] = {"short_lag_semivariance_xyz": gamma_short.tolist(), "knn_explained_share": share}
    where["along_joints"] = along
    where["varies_along"] = [n for n in sorted(along, key=lambda n: -along[n]["knn_explained_share"])
                             if along[n]["knn_explained_share"] > 0.05][:3]
    qs, _, _ = standardize(q)
    names = [n for n in robot.joint_names if n in along]
    pairs = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            cols = [robot.joint_names.index(names[a]), robot.joint_names.index(names[b])]
            share = known.get(tuple(cols))
            if share is None:
                share = knn_share(qs[:, cols])
            pairs.append({"joints": [names[a], names[b]], "knn_explained_share": share})
    pairs.sort(key=lambda r: -r["knn_explained_share"])
    where["along_joint_pairs"] = pairs
    return where, semis



# ---------------------------------------------------------------------------------------
# The measurement scatter, when nobody says what it is
# ---------------------------------------------------------------------------------------
def noise_from_repeats(q: np.ndarray, position: np.ndarray, context_columns: np.ndarray | None = None,
                       min_dof: int = 6) -> NoiseEstimate | None:
    """Pooled within-pose scatter of readings of the same commanded pose, or None.

    q (N, n) and the context (N, c) define a pose; position (N, 3) [m] in any fixed frame
    (same pose, same model prediction: the spread is the instrument's and the robot's
    repeatability). Needs at least ``min_dof`` degrees of freedom.
    """
    keys = np.concatenate([q] + ([context_columns] if context_columns is not None else []), axis=1)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    repeated = np.flatnonzero(counts[inverse] > 1)
    groups = int(np.count_nonzero(counts > 1))
    dof = 3 * (repeated.size - groups)
    if dof < min_dof:
        return None
    sq, copies = 0.0, True
    for g in np.flatnonzero(counts > 1):
        points = position[inverse == g]
        sq += float(np.sum((points - points.mean(axis=0)) ** 2))
        copies = copies and bool(np.all(points == points[0]))
    sigma = math.sqrt(sq / dof)
    # no instrument reads a pose twice to the last digit: a noise floor of 0 divides later. Judged on the
    # readings themselves: the mean of equal numbers can differ from them in the last bit, and sigma with it
    if copies:
        first = np.flatnonzero(inverse == np.flatnonzero(counts > 1)[0])[:2]
        raise InputError(f"the {repeated.size} readings of {groups} repeated poses agree to the last digit: copies "
                         "of one measurement (the same data given twice?), not repeats",
                         parameter="measurements", value=tuple(int(i) for i in first))
    return NoiseEstimate(sigma, "repeated poses", True,
                         f"pooled scatter of {repeated.size} readings of {groups} repeated poses ({dof} dof)")


def noise_from_residual(q: np.ndarray, residual: np.ndarray, n_parameters: int, structured: bool) -> NoiseEstimate:
    """Measurement scatter from a fit's in-sample residual (N, 3) [m] over joint values q (N, n).

    Without structure (the structure test found none) the residual is all scatter:
    sigma^2 = RSS / (3N - p). With structure, only its part that does not vary with the
    joints is scatter: the nugget of the semivariogram of the residual in standardised
    joint space (Gaussian model, :func:`~tcr_accuracy.analysis.semivariogram.fit_gaussian_variogram`),
    capped by the RSS figure. Far from exact when no two poses are close in joint space:
    measuring some poses twice pins it down (:func:`noise_from_repeats`).
    """
    dof = max(residual.size - n_parameters, 1)
    sigma_rss = math.sqrt(float(np.sum(residual**2)) / dof)
    if not structured:
        return NoiseEstimate(sigma_rss, "residual", False,
                             f"final residual without structure, RSS / (3N - p) with {dof} dof")
    qs, _, _ = standardize(q)
    semi = empirical_semivariogram(qs, residual, n_bins=20, standardise=False)
    pooled = EmpiricalSemivariogram(semi.lags, semi.semivariance.mean(axis=1, keepdims=True), semi.counts, None)
    try:
        nugget = float(fit_gaussian_variogram(pooled, 0).nugget)
    except (ValueError, np.linalg.LinAlgError):
        nugget = sigma_rss**2
    sigma = min(math.sqrt(max(nugget, 0.0)), sigma_rss)
    return NoiseEstimate(sigma, "residual nugget", False,
                         "part of the structured final residual that does not vary with the joints "
                         f"(semivariogram at zero joint distance; the whole residual is {sigma_rss * 1e3:.4g} mm "
                         "per axis); measure some poses twice to pin it down")
