"""The one closed-form rigid fit (Kabsch) of the project, and the homogeneous-matrix form of a
transform.

Transforms are named as Pinocchio names them: ``trackerMbase`` maps base-frame points into the
tracker frame, ``p_tracker = trackerMbase @ p_base`` (rotation ``trackerRbase``, translation
``tracker_p_base``). Lengths in m.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..exceptions import InputError


def rigid_fit(nominal, measured) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form rigid transform with ``measured ~ R @ nominal + t`` (least squares).

    Parameters
    ----------
    nominal : array-like of shape (N, 3)
        Points in the base frame [m].
    measured : array-like of shape (N, 3)
        The same points in the tracker frame [m].

    Returns
    -------
    rotation : ndarray of shape (3, 3)
    translation : ndarray of shape (3,)

    Raises
    ------
    InputError
        Fewer than three points, or points (nearly) on one line: then the rotation about
        that line is undetermined.
    """
    nominal = np.asarray(nominal, dtype=float)
    measured = np.asarray(measured, dtype=float)
    if nominal.shape != measured.shape or nominal.ndim != 2 or nominal.shape[1] != 3:
        raise InputError(f"rigid fit: nominal and measured points must both be (N, 3), got {nominal.shape} "
                         f"and {measured.shape}")
    if nominal.shape[0] < 3:
        raise InputError(f"rigid fit: {nominal.shape[0]} points; a tracker frame needs at least 3 poses")
    mn, mm = nominal.mean(axis=0), measured.mean(axis=0)
    spread = np.linalg.svd(nominal - mn, compute_uv=False)
    if spread[1] <= 1e-6 * max(spread[0], 1e-300):
        raise InputError("rigid fit: the nominal TCP positions lie on one line; measure poses that spread in at "
                         "least two directions to fix the tracker frame")
    rot, _ = Rotation.align_vectors(measured - mm, nominal - mn)
    r = rot.as_matrix()
    return r, mm - r @ mn


def homogeneous(rotation, translation) -> np.ndarray:
    """(4, 4) homogeneous matrix of a rotation (3, 3) and a translation (3,) [m]."""
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, translation
    return out
