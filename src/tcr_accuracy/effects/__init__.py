"""The effect library: one module per effect that can open a gap between model and robot.

Each effect is one class in one module of this package, registered below by name (:func:`register`,
in the explicit list :data:`BUILT_IN`); the registered classes are the vocabulary
(:func:`effect_classes`, :func:`vocabulary`, :func:`make_effect`). ``diagnose``,
``simulate``, the CLI and the reports read names, context needs, sign constraints and
display from the classes, the diagnosis' order and options from each class's
:class:`FitPolicy` (:mod:`.fit_policy`) and simulate's draws from its :class:`SimulationRules`
(:mod:`.simulation_rules`), so a new effect is one new file here and one line in
:data:`BUILT_IN`.

Vocabulary (in :func:`vocabulary` order): ``frames``, ``joint_offsets``, ``geometry``,
``compliance``, ``backlash``, ``thermal``, ``transmission``, ``encoder_scale``, ``cyclic``,
``angle_table``, ``clearance``; simulate can also hide ``unmodelled`` and ``link_bending``, which no
diagnosis can name.

The robot the effects describe is ``tcp_poses(robot, q + sum(dq), sum(x))``
(:func:`predict_poses`); :func:`prediction_jacobian` is its Jacobian in the effects'
parameters.
"""

from __future__ import annotations

from .joint_columns import JointColumnsEffect
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
    register,
    unregister,
    vocabulary,
)
from .fit_policy import FitPolicy
from .simulation_rules import SimulationRules
from .compose import (
    parameter_names,
    predict_poses,
    predict_positions,
    prediction_jacobian,
    split_parameters,
    total_perturbation,
)

from .angle_table import AngleTable
from .backlash import Backlash
from .clearance import Clearance
from .compliance import Compliance
from .cyclic import CyclicError
from .drift import Drift
from .encoder_scale import EncoderScale
from .frames import Frames
from .geometry import Geometry
from .joint_offsets import JointOffsets
from .lateral_compliance import LateralCompliance
from .link_bending import LinkBending
from .thermal import Thermal
from .transmission import Transmission
from .unmodelled import Unmodelled

#: The effects the package brings, registered once here (their order in the vocabulary is each
#: class's ``fit_policy.order``, not this list's).
BUILT_IN = (Frames, JointOffsets, Geometry, Compliance, LateralCompliance, LinkBending, Backlash, Thermal,
            EncoderScale, Transmission, CyclicError, AngleTable, Clearance, Drift, Unmodelled)
for _cls in BUILT_IN:
    register(_cls)

__all__ = [
    "BUILT_IN", "Effect", "EffectJacobian", "EffectOutput", "ErrorVectorEffect", "FitPolicy", "JointColumnsEffect",
    "LinearEffect", "PerJointEffect", "SimulationRules", "effect_class", "effect_classes", "make_effect",
    "parameter_names", "plugged_in", "predict_poses", "predict_positions", "prediction_jacobian", "reference_poses",
    "register", "split_parameters", "total_perturbation", "unregister", "vocabulary",
]
