"""Rows of two measurement sets that are the same measurements, to the rounding of their files.

A campaign written twice (re-exported with fewer decimals, or copied under another name) is one
session, not two: given as two, the diagnosis would take every pose for a repeat and halve the
noise floor. A check set that holds the training rows measures the model in-sample, not held
out. Both are found here: a row of one set is a row of the other when its joint values and
its position agree within half the last decimal of the coarser file (:func:`resolution`).
A genuine second session measures the same commanded poses with the tracker's noise (tens of
micrometres) and usually in another tracker frame: it does not agree to the last decimal.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..exceptions import InputError

#: The most decimals a file's numbers are taken to carry (beyond: full double precision).
MAX_DECIMALS = 9


def resolution(values: np.ndarray) -> float:
    """The last decimal of numbers written in text: 10^-d for the fewest decimals d that write
    every one of ``values`` (0 to :data:`MAX_DECIMALS`; 10^-(MAX_DECIMALS + 1) beyond).

    Parameters
    ----------
    values : ndarray
        The numbers as the file wrote them (mm, deg: the file's unit).

    Returns
    -------
    float
    """
    values = np.asarray(values, dtype=float).ravel()
    values = values[np.isfinite(values)]
    for decimals in range(MAX_DECIMALS + 1):
        scaled = values * 10.0**decimals
        if np.all(np.abs(scaled - np.round(scaled)) <= 1e-12 * np.abs(scaled) + 1e-6):  # conversion's rounding
            return 10.0**-decimals
    return 10.0 ** -(MAX_DECIMALS + 1)


#: The units a file may write a joint or a position in, as factors from SI (deg, mm, rad or m).
_UNITS = (180.0 / np.pi, 1e3, 1.0)


def _last_decimal(values: np.ndarray) -> float:
    """Half the last decimal [SI] of values a file wrote in whichever unit writes them with the
    fewest decimals (the file's: values on a grid in one unit are on none in the others)."""
    return 0.5 * max(resolution(values * factor) / factor for factor in _UNITS)


def _tolerances(a, b) -> tuple[np.ndarray, float]:
    """(n_joints,) joint tolerances [rad or m] and the position tolerance [m]: half the coarser
    file's last decimal, each joint column on its own (a prismatic joint is written in mm)."""
    joint = np.array([max(_last_decimal(s.q[:, k]) for s in (a, b)) for k in range(a.q.shape[1])])
    position = max(_last_decimal(s.position) for s in (a, b))
    return joint * (1 + 1e-9) + 1e-12, position * (1 + 1e-9) + 1e-12


def shared_rows(a, b) -> int:
    """How many rows of ``b`` are rows of ``a`` (joint values and position, to the coarser file's
    rounding).

    Parameters
    ----------
    a, b : MeasurementSet
        Measurements of one robot.

    Returns
    -------
    int
    """
    if a.q.shape[1] != b.q.shape[1] or not len(a) or not len(b):
        return 0
    joint, position = _tolerances(a, b)
    tree = cKDTree(a.q / joint)  # each joint in units of its tolerance: one Chebyshev ball of radius 1
    shared = 0
    for row, candidates in enumerate(tree.query_ball_point(b.q / joint, r=1.0, p=np.inf)):
        if candidates and np.any(np.abs(a.position[candidates] - b.position[row]).max(axis=1) <= position):
            shared += 1
    return shared


def check_distinct_sessions(sets: list[MeasurementSet], labels: list[str]) -> None:
    """InputError when one set's rows are all rows of an earlier one: the same campaign written
    twice is one session.

    Parameters
    ----------
    sets : list of MeasurementSet
        The sessions, in order.
    labels : list of str
        Their labels (file names), for the message.
    """
    for j in range(1, len(sets)):
        for i in range(j):
            if len(sets[j]) >= 3 and shared_rows(sets[i], sets[j]) == len(sets[j]):
                raise InputError(f"{sets[j].source}: its {len(sets[j])} rows are rows of {sets[i].source} to the "
                                 f"rounding of the coarser file: the same measurements written twice are one "
                                 f"session, not two (sessions {labels[i]} and {labels[j]}); give each once",
                                 parameter="measurements")
