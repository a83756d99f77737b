"""``geometry``: error screws on the joint placements (link lengths, offsets, axis tilts)."""

from __future__ import annotations

import numpy as np

from ..model.errors import PLACEMENT_COMPONENTS
from ..exceptions import InputError
from .base import ErrorVectorEffect
from .fit_policy import FitPolicy


class Geometry(ErrorVectorEffect):
    """Error screws on every joint placement: ``parentMjoint <- parentMjoint * exp6(xi_j)``.

    Parameters ``geometry.<joint>.<dx|dy|dz|rx|ry|rz>`` [m, rad], the twist components
    in the joint's own frame (link lengths, offsets, axis misalignments). All 6n are
    listed; many are not identifiable from TCP positions (a rotation about a revolute
    joint's own axis is a joint offset; a translation along it can be moved to the next
    placement; the first placement trades against the base frame), so a fit prunes them
    with a rank-revealing QR of its Jacobian. ``components``: a list of
    ``"<joint>.<c>"`` to keep a subset.
    """

    name = "geometry"
    in_words = "link lengths and axis tilts off the drawing"
    summary = "error screws on the joint placements"
    geometric = True
    family = "geometric"
    physics = ("link machining and assembly: a placement off by more than 20 mm or 3 deg is a URDF that describes "
               "another robot")
    fit_policy = FitPolicy(order=20.0)

    def __init__(self, robot, *, components=None) -> None:
        super().__init__(robot)
        self.components = components

    def parameter_names(self):
        names = [f"geometry.{j}.{c}" for j in self.robot.joint_names for c in PLACEMENT_COMPONENTS]
        if self.components is not None:
            keep = {f"geometry.{k}" for k in self.components}
            unknown = keep - set(names)
            if unknown:
                raise InputError(f"geometry: unknown components {sorted(unknown)}")
            names = [n for n in names if n in keep]
        return names

    def parameter_scales(self):
        return np.full(self.n_params, 2e-4)  # 0.2 mm, 0.2 mrad

    def physical_range(self):
        rotation = np.array([n.split(".")[-1].startswith("r") for n in self.parameter_names()])
        bound = np.where(rotation, np.radians(3.0), 0.02)
        return -bound, bound

    def fit_range(self):
        rotation = np.array([n.split(".")[-1].startswith("r") for n in self.parameter_names()])
        bound = np.where(rotation, np.radians(15.0), 0.1)
        return -bound, bound

    def mechanisms(self):
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        wide_lower, wide_upper = self.fit_range()
        return (Mechanism("link_tolerances", "link machining and assembly: lengths, offsets and axis tilts off the "
                          "drawing", "measure the links (or their axes with the tracker, circle point analysis) and "
                          "compare with the drawings' tolerances", lower, upper),
                Mechanism("another_variant", "link dimensions more than 20 mm or 3 deg off the URDF's: the URDF "
                          "describes another variant of the robot, or a link was changed", "compare the URDF with "
                          "the robot's datasheet (variant, link lengths, tool flange)", wide_lower, wide_upper,
                          False))

