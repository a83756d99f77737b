"""A stand-in for the real robot: measurements of a robot with hidden effects.

A *scenario* (YAML file or dict; its format and parsing are
:mod:`tcr_accuracy.analysis.scenario`'s) names the hidden effects and their parameters; the
effects perturb the Pinocchio model (joint values, joint placements), the perturbed
TCP is "measured" with laser-tracker noise, and the result is a
:class:`~tcr_accuracy.io.measurements.MeasurementSet` plus the hidden *truth* (effects and
parameter values). The truth is returned separately and written to its own file, never
into the measurement CSV: a diagnosis judged on simulated data must not see it.

Besides the vocabulary (:func:`~tcr_accuracy.effects.vocabulary`), the registered effects
*outside* it can be hidden, to check that a diagnosis reports structure it cannot explain:
``unmodelled`` (a smooth distortion of one link that depends on several joints at once)
and ``link_bending`` (the longest link sagging as a beam, a translation without rotation).
Everything simulate needs to know about an effect (sign constraints, whether it may be
drawn as the dominant one and how) it reads from the effect's class.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..model.context import MeasurementContext
from ..effects import Effect, effect_class, effect_classes, predict_poses, prediction_jacobian
from ..exceptions import InputError
from ..model.kinematics import tcp_poses
from ..io.measurements import MeasurementSet
from ..model.robot import RobotModel
from ..random_state import renamed_keyword
from .reachable import PoseFilter, Screened, draw_poses
from .scenario import ContextSpec, Scenario, resolve_effect, scenario_from_dict

DEFAULT_NOISE_M = 2e-5  # laser tracker, 0.02 mm per axis
DEFAULT_ORIENTATION_NOISE_RAD = 5e-5


def outside_vocabulary() -> tuple[str, ...]:
    """Effects simulate can hide although no diagnosis can name them."""
    return tuple(n for n, c in effect_classes(vocabulary_only=False).items() if not c.fit_policy.in_vocabulary)


def dominant_candidates() -> tuple[str, ...]:
    """Effects random_scenario may make dominant, in their draw order (``simulation.dominant_place``)."""
    ranked = [(c.simulation.dominant_place, n) for n, c in effect_classes().items()
              if c.simulation.dominant_place is not None]
    return tuple(n for _, n in sorted(ranked))


# ---------------------------------------------------------------------------------------
# Sampling poses and context
# ---------------------------------------------------------------------------------------
def sample_poses(robot: RobotModel, n: int, rng: np.random.Generator, box=None, *,
                 pose_filter: PoseFilter | None = None) -> np.ndarray:
    """(n, n_joints) joint values uniform within the limits; a joint with a URDF ``<mimic>`` rule
    on another chain joint follows it (rows where it would leave its limits are drawn again).

    box : array-like of shape (3, 2), optional
        [[xmin, xmax], [ymin, ymax], [zmin, zmax]] [m]: keep only poses whose nominal
        TCP lies inside (rejection sampling).
    pose_filter : PoseFilter, optional
        Also reject what it rejects (self-collision, the tracker's line of sight; see
        :mod:`tcr_accuracy.analysis.reachable`); its box, if it has one, replaces ``box``.
        Default: limits, ``<mimic>`` rules and ``box`` only.
    """
    return screened_poses(robot, n, rng, box, pose_filter=pose_filter).q


def screened_poses(robot: RobotModel, n: int, rng: np.random.Generator, box=None, *,
                   pose_filter: PoseFilter | None = None) -> Screened:
    """:func:`sample_poses` with what the filter rejected on the way (:class:`Screened`)."""
    if pose_filter is None:
        pose_filter = PoseFilter.for_robot(robot, box=box, collision=False)
    elif box is not None and pose_filter.box is None:
        pose_filter = replace(pose_filter, box=np.asarray(box, dtype=float))
    screened = draw_poses(pose_filter, n, rng)
    if len(screened.q) < n:
        raise InputError(f"random poses: only {len(screened.q)} of {screened.tried} drawn are "
                         f"{pose_filter.tests} ({screened.rejections()}); need {n}"
                         + (" (is the box within reach?)" if pose_filter.box is not None else ""))
    return screened


def draw_context(robot: RobotModel, spec: ContextSpec, n: int, rng: np.random.Generator) -> MeasurementContext:
    """Per-row payload, temperature and approach directions as the spec says."""
    payload_mass = robot.typical_payload_kg if spec.payload_kg is None else float(spec.payload_kg)
    payload = np.where(rng.uniform(size=n) < spec.payload_fraction, payload_mass, 0.0)
    temperature = float(spec.temperature_c) + float(spec.temperature_spread_c) * rng.uniform(-1.0, 1.0, n)
    if spec.directions == "random":
        direction = rng.choice([-1.0, 1.0], size=(n, robot.n_joints))
    else:
        direction = np.zeros((n, robot.n_joints))
    return MeasurementContext(payload, temperature, direction, rng=rng)


# ---------------------------------------------------------------------------------------
# Simulation
# ---------------------------------------------------------------------------------------
@dataclass
class HiddenEffect:
    """One resolved hidden effect: the instance and its parameter values [SI]."""

    effect: Effect
    params: np.ndarray
    in_vocabulary: bool


def _signature(robot, effect, params, q, context) -> np.ndarray:
    """(N, 3) TCP displacement the effect alone causes [m]."""
    nominal = tcp_poses(robot, q).position
    return predict_poses(robot, [effect], [params], q, context).position - nominal


@renamed_keyword("rng", "random_state")
def simulate_measurements(robot: RobotModel, scenario: Scenario | dict, n: int, random_state=None,
                          noise_m: float | None = None, *, q: np.ndarray | None = None,
                          context: MeasurementContext | None = None, box=None, orientation: bool = False,
                          orientation_noise_rad: float = DEFAULT_ORIENTATION_NOISE_RAD,
                          pose_filter: PoseFilter | None = None) -> tuple[MeasurementSet, dict]:
    """Measurements of the robot with the scenario's hidden effects.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot (its model is never changed).
    scenario : Scenario or dict
        Hidden effects (see the module docstring); a dict is read as the YAML would be.
    n : int
        Number of measurements (ignored when q is given).
    random_state : int, numpy.random.Generator or None, default=None
        Draws the poses, context and noise (formerly ``rng``).
    noise_m : float, optional
        Tracker noise, isotropic normal std per axis [m]; default the scenario's, else 2e-5.
    q : (N, n_joints), optional
        Commanded joint values [SI]; default random within the limits (or the box).
    context : MeasurementContext, optional
        Given context (e.g. from a pose file); default drawn as the scenario says.
    box : (3, 2), optional
        Task box for the random poses [m].
    orientation : bool
        Also "measure" the TCP orientation (quaternions with orientation_noise_rad).
    orientation_noise_rad : float
        Standard deviation of the measured orientation's random rotation [rad].
    pose_filter : PoseFilter, optional
        What else a random pose must pass (self-collision, the tracker's line of sight: see
        :func:`sample_poses`); default the joint limits, ``<mimic>`` rules and ``box`` only.

    Returns
    -------
    (MeasurementSet, truth): truth is a JSON-ready dict of the hidden effects and their
    parameters [SI], the noise, and the context settings.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> scenario = {"effects": {"joint_offsets": {"offsets_deg": {"j2": 0.03}}}, "noise_mm": 0.02}
    >>> measured, truth = tcr.simulate_measurements(robot, scenario, 50, random_state=1)
    >>> measured.position.shape
    (50, 3)
    """
    rng = np.random.default_rng(random_state)
    if isinstance(scenario, dict):
        scenario = scenario_from_dict(scenario)
    if q is None:
        if n < 1:
            raise InputError(f"n={n}: need at least one measurement", parameter="n", value=n)
        q = sample_poses(robot, n, rng, box, pose_filter=pose_filter)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = q.shape[0]
    if context is None:
        context = draw_context(robot, scenario.context, n, rng)
    elif context.rng is None:
        context = MeasurementContext(context.payload_kg, context.temperature_c, context.direction, rng,
                                     context.outside_q, context.session, context.time_s, context.order)
    noise = noise_m if noise_m is not None else (scenario.noise_m if scenario.noise_m is not None
                                                  else DEFAULT_NOISE_M)
    if noise < 0:
        raise InputError(f"noise {noise} m: must be >= 0")
    hidden = []
    for name, spec in scenario.effects.items():
        effect, params, tcp_rms = resolve_effect(robot, name, spec, rng, scenario.source)
        if tcp_rms is not None:
            if effect.stochastic:
                raise InputError(f"{scenario.source}: effects.{name}.tcp_rms_mm: not for a random effect")
            sig = _signature(robot, effect, params, q, context)
            rms = float(np.sqrt(np.mean(np.sum(sig**2, axis=1))))
            if rms == 0.0:
                raise InputError(f"{scenario.source}: effects.{name}: zero TCP displacement, cannot scale "
                                 "to tcp_rms_mm")
            params = params * (tcp_rms / rms)  # every effect is linear in its parameters
        hidden.append(HiddenEffect(effect, params, effect.fit_policy.in_vocabulary))
    poses = predict_poses(robot, [h.effect for h in hidden], [h.params for h in hidden], q, context)
    position = poses.position + noise * rng.standard_normal((n, 3))
    quaternion = None
    if orientation:
        tilt = Rotation.from_rotvec(orientation_noise_rad * rng.standard_normal((n, 3)))
        xyzw = (tilt * Rotation.from_matrix(poses.rotation)).as_quat()
        quaternion = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    mset = MeasurementSet(
        joint_names=list(robot.joint_names), q=q, position=position, quaternion=quaternion,
        payload_kg=context.payload_kg.copy(), temperature_c=context.temperature_c.copy(),
        direction=None if not np.any(context.direction) else context.direction.copy(),
        source="simulated",
    )
    truth = {
        "robot": robot.name,
        "n": int(n),
        "noise_m": float(noise),
        "orientation_noise_rad": float(orientation_noise_rad) if orientation else None,
        "context": {"payload_kg": None if scenario.context.payload_kg is None else float(scenario.context.payload_kg),
                    "payload_fraction": float(scenario.context.payload_fraction),
                    "temperature_c": float(scenario.context.temperature_c),
                    "temperature_spread_c": float(scenario.context.temperature_spread_c),
                    "directions": scenario.context.directions},
        "effects": {h.effect.name: _effect_truth(h, robot, q, context) for h in hidden},
        "outside_vocabulary": [h.effect.name for h in hidden if not h.in_vocabulary],
    }
    return mset, truth


def _effect_truth(hidden: HiddenEffect, robot, q, context) -> dict:
    effect = hidden.effect
    out = {
        "parameters": {n: float(v) for n, v in zip(effect.parameter_names(), hidden.params)},
        "units": dict(zip(effect.parameter_names(), effect.parameter_units())),
        "in_vocabulary": hidden.in_vocabulary,
        "options": {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                    for k, v in effect.options.items() if k != "rng"},
    }
    if not effect.stochastic:
        sig = _signature(robot, effect, hidden.params, q, context)
        out["tcp_rms_m"] = float(np.sqrt(np.mean(np.sum(sig**2, axis=1))))
    return out


# ---------------------------------------------------------------------------------------
# Random scenarios for blind benchmarks
# ---------------------------------------------------------------------------------------
@renamed_keyword("rng", "random_state")
def random_scenario(robot: RobotModel, random_state=None, dominant: list[str] | None = None, *,
                    n_dominant: int | None = None, outside: str | None = None, clearance: bool = False,
                    dominance: float = 3.0, noise_m: float = DEFAULT_NOISE_M, beyond_physics: float = 0.0) -> dict:
    """A scenario with realistic magnitudes: geometry always, plus one or two dominant effects.

    Magnitudes (tool-changer scale; the same for other arms): base frame 20 mm / 5 mrad,
    TCP offset 1 mm; geometry 0.1-0.5 mm and 0.1-0.5 mrad per component; joint offsets
    0.01-0.05 deg; and for the dominant effect(s) compliance 0.5-3 mm RMS TCP sag,
    backlash 0.01-0.05 deg per joint, thermal alpha 1.0e-5..2.4e-5 /K over +-10 K,
    transmission 0.005-0.02 deg, encoder scale 1e-4..5e-4.

    The dominant effects are made to dominate: measured on reference poses after the
    best rigid frame fit, the first dominant effect moves the TCP at least ``dominance``
    times as much as geometry and joint offsets together. The background is shrunk
    (down to a fifth) before the dominant effect is scaled up, so realistic ranges hold
    where possible; the factors used are in the returned ``notes``.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    random_state : int, numpy.random.Generator or None, default=None
        Draws the effects and their sizes (formerly ``rng``).
    dominant : list of str, optional
        Effects to make dominant; default one or two drawn from :func:`dominant_candidates`.
    n_dominant : int, optional
        How many to draw when dominant is None (default 1 or 2 at random).
    outside : str, optional
        Also hide an effect outside the vocabulary (``unmodelled`` or ``link_bending``),
        about as large as the dominant effect.
    clearance : bool
        Add joint clearance (a few hundredths of a mm of scatter).
    dominance : float
        How many times as much as the background the first dominant effect moves the TCP.
    noise_m : float
        Tracker noise of the scenario, std per axis [m].
    beyond_physics : float, default=0.0
        Chance that a dominant effect is drawn as the other mechanism with its signature, a sign
        or size its own physics does not have (joints against gravity, ahead of their motion, a
        length scale of an instrument, degrees of gear harmonics: ``SimulationRules.beyond_physics``).

    Returns
    -------
    dict: a scenario with explicit SI parameters, plus ``dominant`` (ordered, largest
    first) and ``notes``.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> scenario = tcr.random_scenario(tcr.load_robot("ur5"), random_state=0, dominant=["compliance"])
    >>> scenario["dominant"]
    ['compliance']
    """
    rng = np.random.default_rng(random_state)
    candidates = dominant_candidates()
    if dominant is None:
        k = n_dominant if n_dominant is not None else int(rng.integers(1, 3))
        dominant = [str(name) for name in rng.choice(candidates, size=k, replace=False)]
    for name in dominant:
        if name not in candidates:
            raise InputError(f"dominant effect {name!r}: choose from {', '.join(candidates)}")
    if outside is not None and outside not in outside_vocabulary():
        raise InputError(f"outside effect {outside!r}: choose from {', '.join(outside_vocabulary())}")
    u = rng.uniform
    specs: dict[str, dict] = {
        "frames": {"spread_mm": {"base": 20.0, "tool": 1.0}, "spread_mrad": {"base": 5.0}},
        "geometry": {"spread_mm": u(0.1, 0.5), "spread_mrad": u(0.1, 0.5)},
        "joint_offsets": {"spread_deg": u(0.01, 0.05), "spread_mm": u(0.01, 0.05)},
    }
    for name in dominant:
        effect = effect_class(name)(robot)
        specs[name] = effect.simulation.dominant_spec(effect, rng)
    if clearance:
        specs["clearance"] = {"axial_mm": 0.005, "radial_mm": 0.005, "tilt_mrad": 0.005}
    context = {"payload_fraction": 0.5, "temperature_spread_c": 10.0, "directions": "random"}

    # resolve to explicit SI values on reference rows, then enforce dominance
    ref_rng = np.random.default_rng(rng.integers(2**63))
    q_ref = sample_poses(robot, 400, ref_rng)
    ctx_ref = draw_context(robot, ContextSpec(**context), 400, ref_rng)
    resolved, beyond = {}, []
    for name, spec in specs.items():
        effect, params, tcp_rms = resolve_effect(robot, name, spec, rng, "random_scenario", lenient=True)
        if name in dominant:
            params = effect.simulation.finish_dominant(effect, params, rng)
            if beyond_physics > 0 and rng.uniform() < beyond_physics:
                other = effect.simulation.beyond_physics(effect, params, rng)
                if other is not None:
                    params = other
                    beyond.append(name)
        if tcp_rms is not None:
            sig = _signature(robot, effect, params, q_ref, ctx_ref)
            params = params * tcp_rms / max(float(np.sqrt(np.mean(np.sum(sig**2, axis=1)))), 1e-300)
        resolved[name] = (effect, params)
    frames = resolved["frames"][0]

    def after_frames(names):
        effects = [resolved[k][0] for k in names]
        params = [resolved[k][1] for k in names]
        sig = (predict_poses(robot, effects, params, q_ref, ctx_ref).position
               - tcp_poses(robot, q_ref).position)
        jac = prediction_jacobian(robot, [frames], [frames.zeros()], q_ref, ctx_ref).reshape(-1, frames.n_params)
        coef, *_ = np.linalg.lstsq(jac, sig.reshape(-1), rcond=None)
        return float(np.sqrt(np.mean((sig.reshape(-1) - jac @ coef) ** 2) * 3))

    strength = {name: after_frames([name]) for name in dominant}
    order = sorted(dominant, key=lambda k: -strength[k])
    background = after_frames(["geometry", "joint_offsets"])
    notes = {"background_factor": 1.0, "dominant_factor": 1.0}
    need = dominance * background / max(strength[order[0]], 1e-300)
    if need > 1.0:
        # the dominant effects grow only as far as their physics allows (a real robot's
        # parameters are inside their physical ranges), the background shrinks for the rest
        room = min(_physical_room(*resolved[name], beyond=name in beyond) for name in dominant)
        grow = min(max(need * 0.2, 1.0), room)
        shrink = max(grow / need, 0.02)
        for name in ("geometry", "joint_offsets"):
            resolved[name] = (resolved[name][0], resolved[name][1] * shrink)
        notes["background_factor"] = shrink
        if grow > 1.0:
            for name in dominant:
                resolved[name] = (resolved[name][0], resolved[name][1] * grow)
            notes["dominant_factor"] = grow
    if outside is not None:
        effect = effect_class(outside)(robot)
        params = effect.parameter_scales()
        sig = _signature(robot, effect, params, q_ref, ctx_ref)
        target = after_frames([order[0]])
        resolved[outside] = (effect, params * target / max(float(np.sqrt(np.mean(np.sum(sig**2, axis=1)))), 1e-300))
    scenario = {
        "effects": {name: {"parameters": {n: float(v) for n, v in zip(e.parameter_names(), p)},
                           **({"options": {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                           for k, v in e.options.items()}} if e.options else {})}
                    for name, (e, p) in resolved.items()},
        "context": context,
        "noise_m": float(noise_m),
        "dominant": [str(k) for k in order],
        "outside_vocabulary": [outside] if outside else [],
        "beyond_physics": beyond,
        "notes": {k: float(v) for k, v in notes.items()},
    }
    return _plain(scenario)


def _physical_room(effect, params: np.ndarray, beyond: bool = False) -> float:
    """How many times the parameters can grow and stay inside the effect's physical range (its fit
    range, every mechanism's, for a draw beyond its own physics)."""
    lower, upper = effect.fit_range() if beyond else effect.physical_range()
    params = np.asarray(params, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(params > 0, upper / params, np.where(params < 0, lower / params, np.inf))
    return float(np.min(room)) if room.size else np.inf


def _plain(value):
    """The same nested value in plain Python types (str keys; float, int, bool, str, list
    values), so that ``yaml.safe_dump`` and ``json.dumps`` take it as it is."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, np.str_):
        return str(value)
    return value


def truth_text(truth: dict, path: str | Path) -> str:
    """The hidden truth as the text of the file ``path`` (not written here): YAML for a
    ``.yaml``/``.yml`` name, JSON for any other."""
    import json

    import yaml

    if Path(path).suffix.lower() in (".yaml", ".yml"):
        return yaml.safe_dump(truth, sort_keys=False)
    return json.dumps(truth, indent=2, allow_nan=False) + "\n"
