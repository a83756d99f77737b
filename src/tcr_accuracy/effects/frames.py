"""``frames``: the tracker's frame and the TCP offset, which every measurement carries."""

from __future__ import annotations

import numpy as np

from ..model.errors import PLACEMENT_COMPONENTS
from .base import ErrorVectorEffect


class Frames(ErrorVectorEffect):
    """Unknown base (tracker) frame and TCP offset.

    Parameters: ``frames.base.dx .. rz`` (a twist applied on the left of the whole
    chain: the measurement frame relative to the robot's base) and ``frames.tool.dx,
    dy, dz`` (the TCP offset in the TCP frame), plus ``frames.tool.rx, ry, rz`` with
    ``tool_rotation=True`` (only identifiable when orientation is measured).
    Exact for large base transforms: the twist goes through ``exp6``.
    """

    name = "frames"
    order = 0.0
    summary = "tracker frame and TCP offset"
    geometric = True
    physics = "the tracker's frame and where the reflector sits on the tool belong to the setup, not the robot: unbounded"

    def __init__(self, robot, *, tool_rotation: bool = False) -> None:
        super().__init__(robot)
        self.tool_rotation = tool_rotation

    def _tool_components(self) -> tuple[str, ...]:
        return PLACEMENT_COMPONENTS if self.tool_rotation else PLACEMENT_COMPONENTS[:3]

    def parameter_names(self):
        return ([f"frames.base.{c}" for c in PLACEMENT_COMPONENTS]
                + [f"frames.tool.{c}" for c in self._tool_components()])

    def parameter_scales(self):
        # the tracker sits anywhere: centimetres and degrees; the TCP offset: a millimetre
        scales = {"base.d": 1e-2, "base.r": 1e-2, "tool.d": 1e-3, "tool.r": 1e-3}
        return np.array([scales[".".join(n.split(".")[1:])[:6]] for n in self.parameter_names()])

