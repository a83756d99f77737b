"""Checks of training data that the joint-space estimators share."""

from __future__ import annotations

from ..exceptions import InputError


def check_enough_points(n_samples: int, n_features: int, who: str) -> None:
    """Raise InputError unless there are more training rows than joints (features)."""
    if n_samples <= n_features:
        raise InputError(
            f"{who}: needs more training points than joints, got n_samples = {n_samples} for "
            f"{n_features} joints; measure at least {n_features + 1} (the seed used 160 for 6)")
