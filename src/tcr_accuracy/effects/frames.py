"""``frames``: the tracker's frame and the TCP offset, which every measurement carries."""

from __future__ import annotations

import numpy as np

from ..model.errors import PLACEMENT_COMPONENTS
from .base import EffectJacobian, ErrorVectorEffect
from .fit_policy import FitPolicy


class Frames(ErrorVectorEffect):
    """Unknown base (tracker) frame and TCP offset.

    Parameters: ``frames.base.dx .. rz`` (a twist applied on the left of the whole
    chain: the measurement frame relative to the robot's base) and ``frames.tool.dx,
    dy, dz`` (the TCP offset in the TCP frame), plus ``frames.tool.rx, ry, rz`` with
    ``tool_rotation=True`` (only identifiable when orientation is measured).
    Exact for large base transforms: the twist goes through ``exp6``.

    ``sessions``: labels of the measurement sessions (tracker stations, days) when there is
    more than one: each has its own tracker frame, ``frames.base.<session>.dx .. rz``, applied
    to the rows of that session (``context.session``); the TCP offset is shared.
    """

    name = "frames"
    in_words = "the tracker's frame and the TCP offset"
    summary = "tracker frame and TCP offset"
    geometric = True
    family = "setup"
    physics = "the tracker's frame and where the reflector sits on the tool belong to the setup, not the robot: unbounded"
    fit_policy = FitPolicy(order=0.0)

    def __init__(self, robot, *, tool_rotation: bool = False, sessions=None) -> None:
        super().__init__(robot)
        self.tool_rotation = tool_rotation
        self.sessions = sessions

    def _tool_components(self) -> tuple[str, ...]:
        return PLACEMENT_COMPONENTS if self.tool_rotation else PLACEMENT_COMPONENTS[:3]

    def _session_labels(self) -> list[str] | None:
        """Parameter-name labels of the sessions (dots replaced), or None for one session."""
        if self.sessions is None or len(self.sessions) < 2:
            return None
        return [str(s).replace(".", "_") for s in self.sessions]

    def parameter_names(self):
        sessions = self._session_labels()
        base = ([f"frames.base.{c}" for c in PLACEMENT_COMPONENTS] if sessions is None else
                [f"frames.base.{s}.{c}" for s in sessions for c in PLACEMENT_COMPONENTS])
        return base + [f"frames.tool.{c}" for c in self._tool_components()]

    def parameter_scales(self):
        # the tracker sits anywhere: centimetres and degrees; the TCP offset: a millimetre
        return np.array([1e-2 if n.startswith("frames.base.") else 1e-3 for n in self.parameter_names()])

    def parameter_jacobian(self, params, q, context):
        sessions = self._session_labels()
        if sessions is None:
            return super().parameter_jacobian(params, q, context)
        q = np.atleast_2d(np.asarray(q, dtype=float))
        em = self.error_model
        n, k = q.shape[0], self.n_params
        index = np.zeros(n, dtype=int) if context is None or context.session is None else \
            np.asarray(context.session, dtype=int)
        dx = np.zeros((n, em.size, k))
        base = np.arange(em.base_slice.start, em.base_slice.stop)
        for s in range(len(sessions)):
            rows = np.flatnonzero(index == s)
            dx[np.ix_(rows, base, 6 * s + np.arange(6))] = np.eye(6)
        for c, name in enumerate(self.parameter_names()[6 * len(sessions):], start=6 * len(sessions)):
            dx[:, em.index(name[len("frames."):]), c] = 1.0
        return EffectJacobian(x=dx)

