"""The effect library: one module per effect that can open a gap between model and robot.

Every module of this package that defines an :class:`Effect` subclass with a ``name``
plugs it in: importing the package imports them all, and the classes are the registry
(:func:`effect_classes`, :func:`vocabulary`, :func:`make_effect`). ``diagnose``,
``simulate``, the CLI and the reports read names, order, context needs, sign
constraints and display from the classes, so a new effect is one new file here.

Vocabulary (in :func:`vocabulary` order): ``frames``, ``joint_offsets``, ``geometry``,
``compliance``, ``backlash``, ``thermal``, ``transmission``, ``encoder_scale``,
``clearance``; simulate can also hide ``unmodelled`` and ``link_bending``, which no
diagnosis can name.

The robot the effects describe is ``tcp_poses(robot, q + sum(dq), sum(x))``
(:func:`predict_poses`); :func:`prediction_jacobian` is its Jacobian in the effects'
parameters.
"""

from __future__ import annotations

import importlib
import pkgutil

from .base import (
    Effect,
    EffectJacobian,
    EffectOutput,
    ErrorVectorEffect,
    LinearEffect,
    PerJointEffect,
    effect_class,
    effect_classes,
    make_effect,
    plugged_in,
    reference_poses,
    unregister,
    vocabulary,
)
from .compose import (
    parameter_names,
    predict_poses,
    predict_positions,
    prediction_jacobian,
    split_parameters,
    total_perturbation,
)

_INFRASTRUCTURE = {"base", "compose"}

for _module in pkgutil.iter_modules(__path__):
    if _module.name not in _INFRASTRUCTURE and not _module.name.startswith("_"):
        importlib.import_module(f"{__name__}.{_module.name}")

__all__ = [
    "Effect", "EffectJacobian", "EffectOutput", "ErrorVectorEffect", "LinearEffect", "PerJointEffect", "effect_class",
    "effect_classes", "make_effect", "parameter_names", "plugged_in", "predict_poses", "predict_positions",
    "prediction_jacobian", "reference_poses", "split_parameters", "total_perturbation", "unregister",
    "vocabulary",
]
