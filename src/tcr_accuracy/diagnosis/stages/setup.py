"""What each measurement session owns: a tracker frame, a TCP offset, both or neither, chosen on
held-out error like an effect.

A campaign of several sessions (a ``session`` column, or several files) shares the robot; what
differs between sessions belongs to the setup. The tracker may have been moved (each session its
own tracker frame: 6 parameters more per session), the reflector re-seated on the tool (each its
own TCP offset: 3 more), both, or neither (one frame and one offset for the whole campaign). Each
is a model of the setup (:class:`~tcr_accuracy.effects.frames.Frames` with ``session_frames`` and
``session_tools``), compared on the repeated k-fold held-out error, the rows of a pose held out
together, so that a session's frame or offset is fitted on its own training rows; the one kept is
the simplest within one standard error of the best (paired over the same rows,
:func:`~tcr_accuracy.diagnosis.ambiguity.one_standard_error_choice`).

The comparison is made twice: with frames alone before the selection (what the selection is run
with), and with the chosen robot effects after it (what the answer says); where the second differs
from the first the selection runs again with it. Where the sessions' own registrations turn too far
apart for one frame to map them (:data:`~.register.SHARED_FRAME_REACH`) each session keeps its own
tracker frame, and only its TCP offset is the data's choice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..ambiguity import one_standard_error_choice
from ..bases import ordered
from ..fitting import FitEngine
from ..paired import row_squares
from .candidates import build_bases, frames_fit_point, frames_jacobians, relinearise
from .register import RegisteredMeasurements

#: The setups, simplest first: (name, a tracker frame per session, a TCP offset per session).
SETUPS = (("one frame", False, False), ("tool offset per session", False, True),
          ("frame per session", True, False), ("frame and tool offset per session", True, True))


@dataclass(frozen=True)
class SessionSetup:
    """What each session owns, and how the data chose it (SI units).

    Attributes
    ----------
    chosen : str
        One of :data:`SETUPS`' names.
    session_frames, session_tools : bool
        Whether each session has its own tracker frame, its own TCP offset.
    forced : str
        Why the tracker frames were not the data's choice (the tracker moved too far); empty
        otherwise.
    compared : tuple of dict
        Each setup tried: ``setup``, ``n_parameters``, ``heldout_rms`` [m], ``within_one_se`` (of the
        best), in :data:`SETUPS`' order.
    judged_with : tuple of str
        The effects of the model the setups were compared in (``frames`` alone, or the selection's).
    sizes : tuple of dict
        Per session after the first, what it owns beyond the first session's: ``session``, and with
        its own frame ``translation`` [m], ``rotation`` [rad] with their standard errors, with its own
        offset ``tool_offset`` (3,) [m] and ``tool_offset_std`` (3,) [m].
    reselected : bool
        Whether the selection ran again with this setup (the one chosen with frames alone differed).
    preferred : str
        The setup the comparison itself prefers, where another was kept (the selection had run with
        it twice); empty otherwise.
    """

    chosen: str
    session_frames: bool
    session_tools: bool
    forced: str
    compared: tuple
    judged_with: tuple
    sizes: tuple = ()
    reselected: bool = False
    preferred: str = ""

    @property
    def options(self) -> dict:
        """The frames effect's options for this setup."""
        return {"session_frames": self.session_frames, "session_tools": self.session_tools}

    def to_dict(self) -> dict:
        out = {"chosen": self.chosen, "session_frames": self.session_frames, "session_tools": self.session_tools,
               "judged_with": list(self.judged_with), "reselected": self.reselected,
               "compared": [{"setup": c["setup"], "n_parameters": c["n_parameters"],
                             "heldout_rms_mm": c["heldout_rms"] * 1e3, "within_one_se": c["within_one_se"]}
                            for c in self.compared],
               "sessions": [_size_dict(s) for s in self.sizes]}
        if self.forced:
            out["forced"] = self.forced
        if self.preferred:
            out["preferred"] = self.preferred
        return out


def _size_dict(size: dict) -> dict:
    out = {"session": size["session"], "against": size["first"]}
    if "translation" in size:
        out.update(translation_mm=size["translation"] * 1e3, translation_std_mm=size["translation_std"] * 1e3,
                   rotation_mrad=size["rotation"] * 1e3, rotation_std_mrad=size["rotation_std"] * 1e3)
    if "tool_offset" in size:
        out.update(tool_offset_mm=[v * 1e3 for v in size["tool_offset"]],
                   tool_offset_std_mm=[v * 1e3 for v in size["tool_offset_std"]])
    return out


def _setups(registered: RegisteredMeasurements) -> list:
    """The setups the data may choose among (a frame per session only, where the tracker moved)."""
    return [s for s in SETUPS if s[1] or not registered.own_frames]


def _frames_basis(registered: RegisteredMeasurements, session_frames: bool, session_tools: bool, jacobians=None):
    """The frames effect of one setup on every part, linearised at ``jacobians`` (per part, the error
    Jacobians; None: at its own frames-only fit)."""
    parts = list(registered.parts)
    bases, _, _ = build_bases(parts, ["frames"], registered.measured_context, [], registered.session_labels,
                              {"session_frames": session_frames, "session_tools": session_tools})
    if jacobians is None:
        jacobians = frames_jacobians(parts, frames_fit_point(parts, bases["frames"]))
    relinearise(bases, jacobians)
    return bases["frames"]


def compare_setups(registered: RegisteredMeasurements, folds, *, rank_tol: float, min_motion: float,
                   effects=("frames",), bases: dict | None = None, jacobians=None, keep: str | None = None) -> SessionSetup:
    """Each setup's held-out error in one model, and the one the data choose.

    Parameters
    ----------
    registered : RegisteredMeasurements
        Stage 1's result, with more than one session.
    folds : list of list of (train, test)
        The repeated k-fold assignments (a pose's rows together).
    rank_tol, min_motion : the engine's identifiability thresholds
    effects : sequence of str
        The model's effects (``frames`` included).
    bases : dict or None
        The other effects' bases (linearised at ``jacobians``), when ``effects`` has more than frames.
    jacobians : list of ndarray or None
        Per part, the error Jacobians the frames are linearised at (None: each setup's own
        frames-only fit).
    keep : str or None
        A setup to keep whatever the comparison prefers (then said in ``preferred``).
    """
    effects = ordered(set(effects) | {"frames"})
    rows = []
    engines = {}
    for name, session_frames, session_tools in _setups(registered):
        frames = _frames_basis(registered, session_frames, session_tools, jacobians)
        engine = FitEngine(list(registered.parts), {**{e: (bases or {})[e] for e in effects if e != "frames"},
                                                     "frames": frames}, folds, rank_tol, min_motion=min_motion)
        r = engine.evaluate(effects, exact=True)
        engines[name] = (engine, r)
        rows.append({"setup": name, "flags": (session_frames, session_tools), "n_parameters": int(r["n_parameters"]),
                     "heldout_rms": float(r["heldout_stats"].rms), "_squares": row_squares(r["heldout_squares"]),
                     "size_over_physics": 0.0})
    chosen = preferred = one_standard_error_choice(rows)
    if keep is not None:
        chosen = next(c for c in rows if c["setup"] == keep)
    best = min(rows, key=lambda c: c["_squares"].mean())
    for c in rows:
        d = c["_squares"] - best["_squares"]
        c["within_one_se"] = bool(d.size < 2 or d.mean() <= d.std(ddof=1) / math.sqrt(d.size))
    engine, r = engines[chosen["setup"]]
    return SessionSetup(chosen=chosen["setup"], session_frames=chosen["flags"][0], session_tools=chosen["flags"][1],
                        forced=registered.own_frames, judged_with=tuple(effects),
                        compared=tuple({k: v for k, v in c.items() if not k.startswith("_") and k != "flags"}
                                       for c in rows),
                        sizes=tuple(_sizes(registered, engine, r)),
                        preferred="" if preferred is chosen else preferred["setup"])


def _sizes(registered: RegisteredMeasurements, engine: FitEngine, result: dict) -> list[dict]:
    """Per session after the first: its frame's and TCP offset's difference from the first's, with
    standard errors from the fit's (the main measured frame's parameters)."""
    basis = engine.bases["frames"]
    keep = result["keep"]["frames"]
    theta = np.full(len(basis.names), np.nan)
    std = np.full(len(basis.names), np.nan)
    theta[keep] = (result["phi"] * result["scale"])[:keep.size]  # frames come first in the fitted vector
    std[keep] = (result["phi_std"] * result["scale"])[:keep.size]
    value = dict(zip(basis.names, theta))
    spread = dict(zip(basis.names, std))
    labels = [str(s).replace(".", "_") for s in registered.session_labels]
    # the main measured frame's TCP offset (renamed after its frame where several are measured)
    prefix = "frames.tool" if len(registered.parts) == 1 else f"frames.{registered.parts[0].label}"
    out = []
    for label in labels[1:]:
        size = {"session": label, "first": labels[0]}
        base = [f"frames.base.{label}.{c}" for c in ("dx", "dy", "dz", "rx", "ry", "rz")]
        # a move kept whole by identifiability (else not said), against the shared registration's frame
        if all(np.isfinite(value.get(n, np.nan)) for n in base) and not registered.own_frames:
            size.update(_norm("translation", [value[n] for n in base[:3]], [spread[n] for n in base[:3]]))
            size.update(_norm("rotation", [value[n] for n in base[3:]], [spread[n] for n in base[3:]]))
        tool = [f"{prefix}.{label}.{c}" for c in ("dx", "dy", "dz")]
        if all(np.isfinite(value.get(n, np.nan)) for n in tool):
            size["tool_offset"] = tuple(float(value[n]) for n in tool)
            size["tool_offset_std"] = tuple(float(spread[n]) for n in tool)
        if len(size) > 2:
            out.append(size)
    return out


def _norm(key: str, values, stds) -> dict:
    """A vector's length and its standard error (first order: the components' errors along it)."""
    v, s = np.asarray(values, dtype=float), np.asarray(stds, dtype=float)
    length = float(np.linalg.norm(v))
    se = float(np.sqrt(np.sum((v / length) ** 2 * s**2))) if length > 0 else float(np.linalg.norm(s))
    return {key: length, f"{key}_std": se}
