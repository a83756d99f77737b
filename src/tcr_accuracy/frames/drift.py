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
    one, else the measurement order): y_r(t) = c_r + v t for every reference r (its own
    offset, the drift shared). The drift is significant when |v| exceeds ``min_z`` standard
    errors, and it is corrected when it also moves the points by more than the noise over the
    session. Returns the correction to subtract from every measured position (N, 3), the
    per-session report, and the noise the references' scatter about the drift gives (the
    instrument's, independent of the robot), or None without references.
    """
    n = session_of.size
    correction = np.zeros((n, 3))
    report, squares, dof = [], 0.0, 0
    if not references:
        return correction, report, None
    for s in range(n_sessions):
        rows = np.flatnonzero(session_of == s)
        times = [ref[3] for ref in references]
        timed = all(t is not None and np.all(np.isfinite(t[rows])) for t in times)
        axis = np.asarray(times[0], dtype=float)[rows] if timed else np.arange(rows.size, dtype=float)
        centred_t = axis - axis.mean()
        spread = float(centred_t @ centred_t)
        if rows.size < 3 or spread == 0.0:
            continue
        cross = np.zeros(3)
        for _, _, measured, _ in references:
            y = measured[rows] - measured[rows].mean(axis=0)
            cross += centred_t @ y
        velocity = cross / (len(references) * spread)  # [m per unit of the time axis]
        ssr = sum(float(np.sum((measured[rows] - measured[rows].mean(axis=0) - np.outer(centred_t, velocity)) ** 2))
                  for _, _, measured, _ in references)
        free = 3 * (len(references) * rows.size - len(references) - 1)
        sigma = math.sqrt(ssr / max(free, 1))
        std = sigma / math.sqrt(len(references) * spread)
        z = float(np.linalg.norm(velocity) / std) if std > 0 else math.inf
        moved = float(np.linalg.norm(velocity) * np.ptp(axis))
        corrected = bool(z > min_z and moved > sigma)
        if corrected:
            correction[rows] = np.outer(centred_t, velocity)
        squares, dof = squares + ssr, dof + free
        per = 3600.0 if timed else 100.0
        report.append({"session": labels[s] if labels else "all", "references": [r[0] for r in references],
                       "time_axis": "time_s" if timed else "measurement order",
                       ("drift_mm_per_h" if timed else "drift_mm_per_100_rows"): (velocity * per * 1e3).tolist(),
                       "drift_std_mm_per_unit": std * per * 1e3, "z": z, "moved_over_session_mm": moved * 1e3,
                       "scatter_per_axis_mm": sigma * 1e3, "corrected": corrected})
    if not references or dof == 0:
        return correction, report, None
    sigma = math.sqrt(squares / dof)
    noise = NoiseEstimate(sigma, "base references", True,
                          f"scatter of {len(references)} base reference(s) ({', '.join(r[0] for r in references)}) "
                          f"about their drift: the instrument's own noise ({dof} dof)")
    return correction, report, noise
