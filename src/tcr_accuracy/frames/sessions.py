"""Each measurement session's tracker frame: where the instrument stood, registered on its own.

A campaign may move the tracker between sessions (a ``session`` column, or several files):
the robot is the same, the instrument's frame is not. Each session's ``trackerMbase`` is the
closed-form rigid fit (:func:`~tcr_accuracy.frames.rigid.rigid_fit`) of the nominal points to
that session's measured points, with base references (frames fixed to the robot's base) adding
their fixed places. Lengths in m.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import InputError
from .rigid import rigid_fit


def register_sessions(nominal: list[np.ndarray], measured: list[np.ndarray], session_of: np.ndarray,
                      labels: list[str], references=()) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per session, (rotation (3, 3), translation (3,) [m]) with ``p_tracker = R p_base + t``.

    Parameters
    ----------
    nominal, measured : list of ndarray of shape (N, 3)
        Per measured frame, the nominal positions in the base frame and the measured ones in
        the tracker frame [m], row-aligned.
    session_of : ndarray of shape (N,)
        Each row's session (0 .. n_sessions - 1).
    labels : list of str
        The sessions' labels; empty for one session.
    references : list of (frame, position (3,) [m], measured (N, 3) [m], time_s)
        Base references: their fixed place in the base frame, and their measured places
        (the session's mean is used).
    """
    stations = []
    for s in range(max(len(labels), 1)):
        rows = np.flatnonzero(session_of == s)
        if labels and rows.size < 3:
            raise InputError(f"session {labels[s]}: {rows.size} measurements, a session's tracker frame "
                             "needs at least 3")
        fixed = [np.asarray(place, dtype=float)[None] for _, place, _, _ in references]
        seen = [points[rows].mean(axis=0)[None] for _, _, points, _ in references]
        stations.append(rigid_fit(np.concatenate([p[rows] for p in nominal] + fixed),
                                  np.concatenate([m[rows] for m in measured] + seen)))
    return stations


def to_base_frame(points: np.ndarray, session_of: np.ndarray, stations) -> np.ndarray:
    """Tracker-frame points (N, 3) [m] mapped into the base frame by each row's session frame."""
    out = np.empty_like(points)
    for s, (rotation, translation) in enumerate(stations):
        rows = session_of == s
        out[rows] = (points[rows] - translation) @ rotation
    return out
