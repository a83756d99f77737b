"""``lateral_compliance``: joints that tilt across their axis under the gravity wrench they carry."""

from __future__ import annotations

import math

import numpy as np

from ..model.context import MeasurementContext, context_column
from ..model.gravity import gravity_wrench
from ..units import REVOLUTE
from .base import EffectJacobian, LinearEffect, link_mass_factors_option, loaded_joint_scales, reference_poses
from .pose_entries import PoseEntries
from .fit_policy import FitPolicy


class LateralCompliance(LinearEffect):
    """The elastic tilt of each joint about the two axes across it.

    A joint carries the gravity wrench of everything beyond it (arm, payload, and on a
    humanoid the other arm through the torso). Its moment along the axis turns the joint
    (``compliance``); its moment across the axis bends the bearing and the housing, tilting
    the child link by ``theta_c = k_c * m_c`` about each of the two perpendicular axes
    ``c`` of the joint's placement frame (``RobotModel.axis_perpendiculars``: x and y for a
    z-axis joint).

    Implementation: the wrench comes from Pinocchio's RNEA on the robot's whole tree
    (:func:`~tcr_accuracy.model.gravity.gravity_wrench`, at the joint's moving origin), its moment
    is turned into the placement frame (``R(q_j)``), and the tilt is a twist on the joint
    placement, ``parentMjoint <- parentMjoint * exp6(xi)``, with ``xi = (0, w)`` for a
    revolute joint and ``(q a x w, w)`` for a prismatic one (the tilt acts at the moving
    origin). First order in the deflection: the wrench is taken at the commanded pose.

    Parameters ``lateral_compliance.<joint>.<x|y|z>`` (``.u``/``.v`` for an oblique axis)
    [rad/Nm]. Context: ``payload_kg`` per row. ``link_mass_factors`` as for compliance.
    """

    name = "lateral_compliance"
    in_words = "joints tilting under gravity"
    summary = "joint tilt across each axis under the gravity wrench it carries"
    context_columns = ("payload_kg",)
    non_negative = True
    family = "gravity"
    physics = ("a bearing tilts the way the gravity moment pushes it (positive), by less than 2 deg under its "
               "typical moment (200 x the typical compliance)")
    fit_policy = FitPolicy(order=35.0)

    def __init__(self, robot, *, link_mass_factors=None) -> None:
        super().__init__(robot)
        self.link_mass_factors = link_mass_factors_option(robot, link_mass_factors)

    def _axes(self) -> list[tuple[int, str, np.ndarray]]:
        """(joint index, label, unit vector in the placement frame) of every parameter."""
        out = []
        for j, name in enumerate(self.robot.joint_names):
            pair = self.robot.axis_perpendiculars(j)
            coordinate = all(np.max(np.abs(e)) > 1 - 1e-12 for e in pair)
            for e, generic in zip(pair, "uv"):
                label = "xyz"[int(np.argmax(np.abs(e)))] if coordinate else generic
                out.append((j, label, e))
        return out

    def parameter_names(self):
        return [f"lateral_compliance.{self.robot.joint_names[j]}.{label}" for j, label, _ in self._axes()]

    def parameter_units(self):
        return ["rad/Nm"] * self.n_params

    def moments(self, q, context) -> np.ndarray:
        """(N, n_joints, 3) gravity moment each joint carries, in its placement frame [Nm]."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        payload = context_column(context, "payload_kg", q.shape[0], 0.0)
        outside = None if context is None else context.outside_q
        moment = gravity_wrench(self.robot, q, payload, self.link_mass_factors, outside)[:, :, 3:]
        for j, kind in enumerate(self.robot.joint_kinds):
            if kind == REVOLUTE:  # child axes -> placement axes: Rodrigues about the joint axis
                a = self.robot.joint_axis(j)
                m = moment[:, j]
                c, s = np.cos(q[:, j])[:, None], np.sin(q[:, j])[:, None]
                moment[:, j] = m * c + np.cross(a, m) * s + np.outer(m @ a, a) * (1.0 - c)
        return moment

    def parameter_scales(self):
        """Compliances that tilt each joint by 0.01 deg under its RMS moment across the axis
        (reference poses, typical payload); unloaded axes get the median of the others."""
        q_ref = reference_poses(self.robot)
        loaded = MeasurementContext.defaults(q_ref.shape[0], self.robot.n_joints,
                                             payload_kg=self.robot.typical_payload_kg)
        moment = self.moments(q_ref, loaded)
        rms = np.array([np.sqrt(np.mean((moment[:, j] @ e) ** 2)) for j, _, e in self._axes()])
        per_joint = rms.reshape(self.robot.n_joints, 2)
        return loaded_joint_scales(self.robot, per_joint, math.radians(0.01), math.radians(0.01)).reshape(-1)

    def physical_range(self):
        return np.zeros(self.n_params), 200.0 * self.parameter_scales()

    def fit_range(self):
        _, upper = self.physical_range()  # as far against the moment as an elastic bearing goes with it
        return -upper, upper

    def mechanisms(self):
        from .mechanisms import Mechanism

        _, upper = self.physical_range()
        return (Mechanism("elastic_bearing", "joints that tilt across their axis the way the gravity moment pushes "
                          "them: bearing and housing elasticity", "load the tool sideways with a known weight and "
                          "measure the tilt; compare with the bearings' tilting stiffness", np.zeros_like(upper),
                          upper),
                Mechanism("tilt_against_gravity", "joints that tilt against the gravity moment: preloaded or "
                          "misaligned bearings, or a mass model far from the real one", "compare the URDF's masses "
                          "with the real ones; check the bearings' preload", -upper, np.zeros_like(upper), False))

    def parameter_jacobian(self, params, q, context):
        _, entries = self.sparse_parameter_jacobian(params, q, context)
        return EffectJacobian(x=entries.dense(self.error_model.size, self.n_params))

    def sparse_parameter_jacobian(self, params, q, context) -> tuple[EffectJacobian, PoseEntries]:
        """:meth:`parameter_jacobian` as its nonzero entries (:class:`~tcr_accuracy.effects.pose_entries.PoseEntries`):
        each parameter tilts one joint, so it moves that joint's rotation entries (and its translation
        ones for a prismatic joint) and no others."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        moment = self.moments(q, context)
        em = self.error_model
        blocks = []
        for k, (j, _, e) in enumerate(self._axes()):
            start = em.index(f"{self.robot.joint_names[j]}.dx")
            tilt = (moment[:, j] @ e)[:, None] * e  # (N, 3): rotation per unit compliance
            if self.robot.joint_kinds[j] != REVOLUTE:  # tilt about the moving origin
                blocks.append((start, np.cross(q[:, j, None] * self.robot.joint_axis(j), tilt), k))
            blocks.append((start + 3, tilt, k))
        return EffectJacobian(), PoseEntries.of(blocks, q.shape[0])
