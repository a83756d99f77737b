"""The tracker's drift over a session, seen by base references (frames fixed to the robot's
base, whose measured position moves only with the instrument). Lengths in m, time in s.
"""

from __future__ import annotations

import math

import numpy as np

from .noise import NoiseEstimate


def tracker_drift(references: list, session_of: np.ndarray, n_sessions: int, labels: list[str],
                  min_z: float = 3.5) -> tuple[np.ndarray, list, NoiseEstimate | None]:
    """The tracker's drift seen by base references: frames fixed to the robot's base, whose
    measured position changes only with the instrument.

    references : list of (frame, nominal position (3,) [m], measured (N, 3) in the tracker
        frame [m], time_s (N,) or None)
    session_of : (N,) each row's session

    Per session, a translation drift linear in time (``time_s`` where every reference row has
    one and it changes, else the measurement order, said in ``time_axis``): y_r(t) = c_r + v t
    for every reference r (its own offset, the drift shared). A reading off by more than
    :data:`OUTLIER_SIGMAS` robust standard deviations of the references' scatter (a reflector
    bumped, a beam broken) is left out of the fit and of the noise, and listed (``outliers``):
    one reading 5 mm off would otherwise make the instrument ten times noisier than it is. The
    drift is significant when |v| exceeds ``min_z`` standard errors, and it is corrected when
    it also moves the points by more than the noise over the session. Returns the correction to
    subtract from every measured position (N, 3), the per-session report, and the noise the
    references' scatter about the drift gives (the instrument's, independent of the robot), or
    None without references.
    """
    n = session_of.size
    correction = np.zeros((n, 3))
    report, squares, dof, left_out = [], 0.0, 0, 0
    if not references:
        return correction, report, None
    for s in range(n_sessions):
        rows = np.flatnonzero(session_of == s)
        times = [ref[3] for ref in references]
        timed = all(t is not None and np.all(np.isfinite(t[rows])) for t in times)
        how = "time_s"
        if timed and rows.size and np.ptp(np.asarray(times[0], dtype=float)[rows]) == 0.0:
            timed, how = False, "measurement order (time_s is the same on every row)"
        elif not timed:
            how = "measurement order"
        label = labels[s] if labels else "all"
        if rows.size < 3:
            report.append({"session": label, "references": [r[0] for r in references], "time_axis": how,
                           "fitted": False, "why": f"{rows.size} rows: a drift needs at least 3"})
            continue
        axis = np.asarray(times[0], dtype=float)[rows] if timed else np.arange(rows.size, dtype=float)
        readings = [measured[rows] for _, _, measured, _ in references]
        velocity, residuals, keep = _robust_drift(axis, readings)
        ssr = sum(float(np.sum(r[k] ** 2)) for r, k in zip(residuals, keep))
        kept = sum(int(k.sum()) for k in keep)
        free = 3 * (kept - len(references) - 1)
        sigma = math.sqrt(ssr / max(free, 1))
        spread = sum(float(np.sum((axis[k] - axis[k].mean()) ** 2)) for k in keep)
        std = sigma / math.sqrt(spread) if spread > 0 else math.inf
        z = float(np.linalg.norm(velocity) / std) if 0 < std < math.inf else 0.0
        moved = float(np.linalg.norm(velocity) * np.ptp(axis))
        corrected = bool(z > min_z and moved > sigma)
        if corrected:
            correction[rows] = np.outer(axis - axis.mean(), velocity)
        squares, dof = squares + ssr, dof + max(free, 0)
        outliers = [{"reference": ref[0], "row": int(rows[i]), "off_mm": float(np.linalg.norm(r[i]) * 1e3)}
                    for ref, r, k in zip(references, residuals, keep) for i in np.flatnonzero(~k)]
        left_out += len(outliers)
        per = 3600.0 if timed else 100.0
        report.append({"session": label, "references": [r[0] for r in references], "time_axis": how, "fitted": True,
                       ("drift_mm_per_h" if timed else "drift_mm_per_100_rows"): (velocity * per * 1e3).tolist(),
                       "drift_std_mm_per_unit": std * per * 1e3, "z": z, "moved_over_session_mm": moved * 1e3,
                       "scatter_per_axis_mm": sigma * 1e3, "corrected": corrected, "outliers": outliers})
    if dof == 0:
        return correction, report, None
    sigma = math.sqrt(squares / dof)
    noise = NoiseEstimate(sigma, "base references", True,
                          f"scatter of {len(references)} base reference(s) ({', '.join(r[0] for r in references)}) "
                          f"about their drift: the instrument's own noise ({dof} dof"
                          + (f"; {left_out} reading(s) more than {OUTLIER_SIGMAS:g} robust standard deviations off "
                             "left out" if left_out else "") + ")")
    return correction, report, noise


#: A base reference's reading further than this many robust standard deviations (1.4826 x the
#: median absolute residual, per axis) from the drift fit is an outlier: left out and listed.
OUTLIER_SIGMAS = 6.0


def _robust_drift(axis: np.ndarray, readings: list) -> tuple:
    """The shared drift velocity v (3,) [m per unit of ``axis``] of references read at ``axis`` (M,)
    (``readings``: per reference (M, 3) [m]), each with its own offset; fitted by least squares,
    then again without the readings further than :data:`OUTLIER_SIGMAS` robust standard
    deviations from the first fit. Returns (v, residuals per reference (M, 3), kept rows per
    reference (M,) bool)."""
    def fit(keep):
        cross, spread = np.zeros(3), 0.0
        for y, k in zip(readings, keep):
            t = axis[k] - axis[k].mean()
            cross += t @ (y[k] - y[k].mean(axis=0))
            spread += float(t @ t)
        velocity = cross / spread if spread > 0 else np.zeros(3)
        return velocity, [y - y[k].mean(axis=0) - np.outer(axis - axis[k].mean(), velocity)
                          for y, k in zip(readings, keep)]

    keep = [np.ones(axis.size, dtype=bool) for _ in readings]
    velocity, residuals = fit(keep)
    for _ in range(3):
        # each reference's residuals about their median: a far reading shifts its reference's
        # least-squares offset by (its excess) / M, which would otherwise make every other reading of
        # that reference look as far off and leave the far one in
        centred = [r - np.median(r[k], axis=0) for r, k in zip(residuals, keep)]
        scale = 1.4826 * float(np.median(np.abs(np.concatenate([r[k] for r, k in zip(centred, keep)]))))
        fresh = [np.all(np.abs(r) <= OUTLIER_SIGMAS * scale, axis=1) for r in centred]
        if scale <= 0 or all(np.array_equal(f, k) for f, k in zip(fresh, keep)) or \
                any(int(f.sum()) < 2 for f in fresh):
            break
        keep = fresh
        velocity, residuals = fit(keep)
    return velocity, residuals, keep
