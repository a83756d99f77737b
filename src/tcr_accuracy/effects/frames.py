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

    ``sessions``: labels of the measurement sessions (tracker stations, days, payload runs) when
    there is more than one; what each owns is the diagnosis' choice (:mod:`~tcr_accuracy.diagnosis.stages.setup`).
    With ``session_frames`` (the tracker moved between them) every session after the first has its own
    tracker frame, ``frames.base.<session>.dx .. rz`` the twist it adds to the first session's
    ``frames.base.*``; with ``session_tools`` (the reflector re-seated) every session after the first
    has its own TCP offset, ``frames.tool.<session>.dx, dy, dz`` added to the first session's
    ``frames.tool.*``. Each applies to the rows of its session (``context.session``).
    """

    name = "frames"
    in_words = "the tracker's frame and the TCP offset"
    summary = "tracker frame and TCP offset"
    geometric = True
    family = "setup"
    physics = "the tracker's frame and where the reflector sits on the tool belong to the setup, not the robot: unbounded"
    fit_policy = FitPolicy(order=0.0)

    def __init__(self, robot, *, tool_rotation: bool = False, sessions=None, session_frames: bool = True,
                 session_tools: bool = False) -> None:
        super().__init__(robot)
        self.tool_rotation = tool_rotation
        self.sessions = sessions
        self.session_frames = session_frames
        self.session_tools = session_tools

    def _tool_components(self) -> tuple[str, ...]:
        return PLACEMENT_COMPONENTS if self.tool_rotation else PLACEMENT_COMPONENTS[:3]

    def _session_labels(self) -> list[str] | None:
        """Parameter-name labels of the sessions (dots replaced), or None for one session."""
        if self.sessions is None or len(self.sessions) < 2:
            return None
        return [str(s).replace(".", "_") for s in self.sessions]

    def parameter_names(self):
        return [name for name, _, _ in self._columns()]

    def _columns(self) -> list[tuple[str, str, int | None]]:
        """(parameter name, its error-model entry, the session it applies to or None for every row)."""
        tool = [(f"frames.tool.{c}", f"tool.{c}", None) for c in self._tool_components()]
        columns = [(f"frames.base.{c}", f"base.{c}", None) for c in PLACEMENT_COMPONENTS]
        later = list(enumerate(self._session_labels() or []))[1:]
        if self.session_frames:
            columns += [(f"frames.base.{s}.{c}", f"base.{c}", k) for k, s in later for c in PLACEMENT_COMPONENTS]
        columns += tool
        if self.session_tools:
            columns += [(f"frames.tool.{s}.{c}", f"tool.{c}", k) for k, s in later for c in PLACEMENT_COMPONENTS[:3]]
        return columns

    def parameter_scales(self):
        # the tracker sits anywhere: centimetres and degrees; the TCP offset: a millimetre
        return np.array([1e-2 if n.startswith("frames.base.") else 1e-3 for n in self.parameter_names()])

    def parameter_jacobian(self, params, q, context):
        if self._session_labels() is None:
            return super().parameter_jacobian(params, q, context)
        q = np.atleast_2d(np.asarray(q, dtype=float))
        em = self.error_model
        n = q.shape[0]
        session = np.zeros(n, dtype=int) if context is None or context.session is None else \
            np.asarray(context.session, dtype=int)
        columns = self._columns()
        dx = np.zeros((n, em.size, len(columns)))
        for c, (_, entry, only) in enumerate(columns):
            dx[:, em.index(entry), c] = 1.0 if only is None else session == only
        return EffectJacobian(x=dx)
