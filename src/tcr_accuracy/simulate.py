"""A stand-in for the real robot: measurements of a robot with hidden effects.

A *scenario* (YAML file or dict) names the hidden effects and their parameters; the
effects perturb the Pinocchio model (joint values, joint placements), the perturbed
TCP is "measured" with laser-tracker noise, and the result is a
:class:`~tcr_accuracy.measurements.MeasurementSet` plus the hidden *truth* (effects and
parameter values). The truth is returned separately and written to its own file, never
into the measurement CSV: a diagnosis judged on simulated data must not see it.

Scenario format (every key optional)::

    effects:
      frames:                       # the tracker frame and TCP offset
        base_mm: {dx: 25, dy: -40, dz: 10}
        base_mrad: {rz: 8}
      geometry:
        spread_mm: 0.2              # random: normal, this std, for every length parameter
        spread_mrad: 0.2            # ... and every angle parameter
      joint_offsets:
        offsets_deg: {j2: 0.05, j3: -0.03}
      compliance:
        tcp_rms_mm: 1.5             # scale the drawn compliances to this RMS TCP displacement
        options: {link_mass_spread: 0.05}
      thermal:
        alpha_per_k: 1.2e-5
    context:
      payload_kg: 150               # payload of the rows that carry it (default: a disc cutter)
      payload_fraction: 0.5
      temperature_c: 20             # mean; rows spread uniformly by +-temperature_spread_c
      temperature_spread_c: 10
      directions: random            # random +-1 approach directions per joint, or none
    noise_mm: 0.02

Inside an effect, a key ``<label>_<unit>`` gives values: a number for every parameter
of that dimension, or a mapping ``{selector: value}`` where the selector is the
parameter name without the effect prefix (``j3.dy``), or a leading or trailing part of
it (``j3``, ``dy``); a label that is itself a selector restricts the key to those
parameters (``base_mm: {dx: 25}`` sets ``frames.base.dx``). ``spread_<unit>`` draws normal values with that standard deviation
instead. ``parameters`` takes full names in SI (``compliance.j2: 2.0e-8``): a truth file
is a scenario. An effect with no values is drawn around its typical scales.
``tcp_rms_mm`` rescales the effect to that RMS TCP displacement over the simulated rows.
Units: m, mm, um, rad, mrad, urad, deg, arcsec, per_k, ppm_per_k, ppm, rad_per_nm,
urad_per_nm, deg_per_knm, m_per_n, um_per_n, mm_per_kn; no suffix = dimensionless.

Besides the vocabulary (:data:`~tcr_accuracy.effects.EFFECTS`), two effects *outside*
it can be hidden, to check that a diagnosis reports structure it cannot explain:
``unmodelled`` (a smooth distortion of one link that depends on several joints at once)
and ``link_bending`` (the longest link sagging as a beam, a translation without rotation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from .effects import EFFECTS, Effect, EffectOutput, predict_poses, prediction_jacobian, typical_payload_kg
from .exceptions import InputError
from .kinematics import tcp_poses
from .measurements import REFERENCE_TEMPERATURE_C, MeasurementContext, MeasurementSet, read_user_text
from .robot import RobotModel

DEFAULT_NOISE_M = 2e-5  # laser tracker, 0.02 mm per axis
DEFAULT_ORIENTATION_NOISE_RAD = 5e-5

#: unit suffix -> (SI unit, factor to SI)
UNITS: dict[str, tuple[str, float]] = {
    "m": ("m", 1.0), "mm": ("m", 1e-3), "um": ("m", 1e-6),
    "rad": ("rad", 1.0), "mrad": ("rad", 1e-3), "urad": ("rad", 1e-6),
    "deg": ("rad", math.pi / 180.0), "arcsec": ("rad", math.pi / 180.0 / 3600.0),
    "per_k": ("1/K", 1.0), "ppm_per_k": ("1/K", 1e-6), "ppm": ("1", 1e-6),
    "rad_per_nm": ("rad/Nm", 1.0), "urad_per_nm": ("rad/Nm", 1e-6),
    "deg_per_knm": ("rad/Nm", math.pi / 180.0 / 1000.0),
    "m_per_n": ("m/N", 1.0), "um_per_n": ("m/N", 1e-6), "mm_per_kn": ("m/N", 1e-6),
}


# ---------------------------------------------------------------------------------------
# Effects outside the vocabulary (simulation only; diagnose never sees these classes)
# ---------------------------------------------------------------------------------------
def _longest_link(robot: RobotModel) -> int:
    """Index of the joint whose placement carries the longest link (after the first)."""
    lengths = [np.linalg.norm(pl.translation) for pl in robot.joint_placements]
    if len(lengths) > 1:
        lengths[0] = -1.0  # the pedestal trades with the base frame; bend an arm link
    return int(np.argmax(lengths))


class Unmodelled(Effect):
    """A smooth distortion of the longest link that depends on three joints at once.

    The distal joint of the longest link is shifted (translation in its own frame) by
    ``A * (sin(2 q_a + q_b), sin(q_b - 2 q_c + 0.5), cos(3 q_a - q_c))`` with a, b, c the
    first three joints. No effect of the vocabulary has this shape: the distortion
    moves a joint placement with a mix of other joints' angles. Parameter
    ``unmodelled.amplitude`` [m].
    """

    name = "unmodelled"
    analytic_jacobian = False  # finite differences of perturb (base class)

    def parameter_names(self):
        return ["unmodelled.amplitude"]

    def parameter_units(self):
        return ["m"]

    def parameter_scales(self):
        return np.array([3e-4])

    def perturb(self, params, q, context):
        (amplitude,) = self.check_params(params)
        q = np.atleast_2d(q)
        n = self.robot.n_joints
        a, b, c = 0, 1 % n, 2 % n
        shift = amplitude * np.stack([np.sin(2 * q[:, a] + q[:, b]), np.sin(q[:, b] - 2 * q[:, c] + 0.5),
                                      np.cos(3 * q[:, a] - q[:, c])], axis=1)
        em = self.error_model
        x = np.zeros((q.shape[0], em.size))
        start = em.index(f"{self.robot.joint_names[_longest_link(self.robot)]}.dx")
        x[:, start:start + 3] = shift
        return EffectOutput(x=x)


class LinkBending(Effect):
    """The longest link sags under gravity like a cantilever: its far end drops.

    The distal joint of the longest link moves, without turning, by ``A cos(e)`` in the
    direction of gravity's component perpendicular to the link, e = the link's elevation
    above the horizontal. Parameter ``link_bending.tip`` [m]: the drop with the link
    horizontal. Joint compliance turns the distal frames as well; a bending beam
    translates them, so the vocabulary explains this only in part.
    """

    name = "link_bending"
    analytic_jacobian = False  # finite differences of perturb (base class)

    def parameter_names(self):
        return ["link_bending.tip"]

    def parameter_units(self):
        return ["m"]

    def parameter_scales(self):
        return np.array([5e-4])

    def perturb(self, params, q, context):
        (tip,) = self.check_params(params)
        q = np.atleast_2d(q)
        robot = self.robot
        k = _longest_link(robot)
        model = robot.model
        data = model.createData()
        parent = model.parents[k + 1]
        placement = robot.joint_placements[k]
        g = model.gravity.linear / np.linalg.norm(model.gravity.linear)
        em = self.error_model
        x = np.zeros((q.shape[0], em.size))
        start = em.index(f"{robot.joint_names[k]}.dx")
        for i, qi in enumerate(q):
            pin.forwardKinematics(model, data, robot.to_pinocchio_q(qi))
            frame = data.oMi[parent] * placement  # the link's distal end, before its joint moves
            link = data.oMi[parent].rotation @ placement.translation
            u = link / np.linalg.norm(link)
            drop = g - (g @ u) * u  # gravity across the link; |drop| = cos(elevation)
            x[i, start:start + 3] = frame.rotation.T @ (tip * drop)
        return EffectOutput(x=x)


#: Effects simulate can hide although no diagnosis can name them.
OUTSIDE_VOCABULARY: dict[str, type[Effect]] = {"unmodelled": Unmodelled, "link_bending": LinkBending}

#: Effects whose parameters are magnitudes (drawn values are taken as |value|).
NON_NEGATIVE = ("compliance", "backlash", "clearance")

#: Effects random_scenario may make dominant.
DOMINANT_CANDIDATES = ("compliance", "backlash", "thermal", "transmission", "encoder_scale")


def effect_class(name: str, source: str = "scenario") -> type[Effect]:
    if name in EFFECTS:
        return EFFECTS[name]
    if name in OUTSIDE_VOCABULARY:
        return OUTSIDE_VOCABULARY[name]
    raise InputError(f"{source}: unknown effect {name!r}; effects: {', '.join(EFFECTS)}; outside the vocabulary "
                     f"(simulate only): {', '.join(OUTSIDE_VOCABULARY)}")


# ---------------------------------------------------------------------------------------
# Scenario
# ---------------------------------------------------------------------------------------
@dataclass
class ContextSpec:
    """How the simulated context columns are drawn."""

    payload_kg: float | None = None  # None: typical_payload_kg(robot)
    payload_fraction: float = 0.5
    temperature_c: float = REFERENCE_TEMPERATURE_C
    temperature_spread_c: float = 10.0
    directions: str = "random"  # "random" or "none"


@dataclass
class Scenario:
    """Hidden effects (name -> spec as in the YAML) and how to draw context and noise."""

    effects: dict[str, dict] = field(default_factory=dict)
    context: ContextSpec = field(default_factory=ContextSpec)
    noise_m: float | None = None
    source: str = "<scenario>"


@dataclass
class HiddenEffect:
    """One resolved hidden effect: the instance and its parameter values [SI]."""

    effect: Effect
    params: np.ndarray
    in_vocabulary: bool


_CONTEXT_KEYS = {"payload_kg", "payload_fraction", "temperature_c", "temperature_spread_c", "directions"}


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario YAML file (see the module docstring)."""
    import yaml

    path = Path(path)
    text = read_user_text(path, "scenario file")
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    return scenario_from_dict(data or {}, source=str(path))


def scenario_from_dict(data: dict, source: str = "<scenario>") -> Scenario:
    """Check the structure of a scenario mapping and wrap it."""
    if not isinstance(data, dict):
        raise InputError(f"{source}: a scenario is a mapping with keys effects, context, noise_mm")
    unknown = set(data) - {"effects", "context", "noise_mm", "robot", "dominant", "outside_vocabulary",
                           "seed", "n", "orientation_noise_rad", "noise_m", "notes"}
    if unknown:
        raise InputError(f"{source}: unknown key(s) {', '.join(sorted(unknown))} (keys: effects, context, noise_mm)")
    effects = data.get("effects") or {}
    if not isinstance(effects, dict):
        raise InputError(f"{source}: effects: a mapping effect name -> settings")
    for name, spec in effects.items():
        effect_class(name, source)  # raises for unknown names
        if spec is not None and not isinstance(spec, dict):
            raise InputError(f"{source}: effects.{name}: settings must be a mapping (or empty)")
    ctx = data.get("context") or {}
    if not isinstance(ctx, dict) or set(ctx) - _CONTEXT_KEYS:
        raise InputError(f"{source}: context: unknown key(s) {', '.join(sorted(set(ctx) - _CONTEXT_KEYS))} "
                         f"(keys: {', '.join(sorted(_CONTEXT_KEYS))})")
    context = ContextSpec(**{k: ctx[k] for k in ctx})
    if context.directions not in ("random", "none"):
        raise InputError(f"{source}: context.directions: 'random' or 'none', got {context.directions!r}")
    if not 0.0 <= float(context.payload_fraction) <= 1.0:
        raise InputError(f"{source}: context.payload_fraction must lie in [0, 1]")
    noise = None
    if "noise_mm" in data:
        noise = _number(data["noise_mm"], f"{source}: noise_mm") * 1e-3
    elif "noise_m" in data:
        noise = _number(data["noise_m"], f"{source}: noise_m")
    if noise is not None and noise < 0:
        raise InputError(f"{source}: noise must be >= 0")
    return Scenario(effects={k: dict(v or {}) for k, v in effects.items()}, context=context,
                    noise_m=noise, source=source)


def _number(value, where: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {value!r} is not a number") from None
    if not math.isfinite(out):
        raise InputError(f"{where}: non-finite value")
    return out


def _split_unit(key: str) -> tuple[str, str | None]:
    """'offsets_deg' -> ('offsets', 'deg'); the longest known unit suffix wins."""
    best = None
    for unit in UNITS:
        if key.endswith("_" + unit) and (best is None or len(unit) > len(best)):
            best = unit
    if best is None:
        return key, None
    return key[: -len(best) - 1], best


def _selected(sub: str, selector: str) -> bool:
    parts, sel = sub.split("."), str(selector).split(".")
    return parts[: len(sel)] == sel or parts[-len(sel):] == sel


def resolve_effect(robot: RobotModel, name: str, spec: dict, rng: np.random.Generator,
                   source: str = "<scenario>", lenient: bool = False) -> tuple[Effect, np.ndarray, float | None]:
    """Instantiate one hidden effect and draw/convert its parameters to SI.

    lenient: skip value keys whose unit no parameter has (a robot without prismatic
    joints has no length-valued joint offsets) instead of raising.
    Returns (effect, params, tcp_rms_m or None).
    """
    cls = effect_class(name, source)
    where = f"{source}: effects.{name}"
    options = dict(spec.get("options") or {})
    mass_spread = options.pop("link_mass_spread", None)
    if mass_spread is not None:
        spread = _number(mass_spread, f"{where}.options.link_mass_spread")
        options["link_mass_factors"] = np.clip(1.0 + spread * rng.standard_normal(robot.n_joints), 0.1, None)
    if "link_mass_factors" in options:
        options["link_mass_factors"] = np.asarray(options["link_mass_factors"], dtype=float)
    effect = cls(robot, **options)
    names = effect.parameter_names()
    subs = [n[len(name) + 1:] for n in names]
    units = effect.parameter_units()
    values = np.full(len(names), np.nan)
    spreads = np.full(len(names), np.nan)
    tcp_rms = None
    for key, value in spec.items():
        if key == "options":
            continue
        if key == "tcp_rms_mm":
            tcp_rms = _number(value, f"{where}.tcp_rms_mm") * 1e-3
            continue
        if key == "parameters":
            if not isinstance(value, dict):
                raise InputError(f"{where}.parameters: a mapping full parameter name -> SI value")
            for pname, v in value.items():
                if pname not in names:
                    raise InputError(f"{where}.parameters: unknown parameter {pname!r} "
                                     f"(parameters: {', '.join(names)})")
                values[names.index(pname)] = _number(v, f"{where}.parameters.{pname}")
            continue
        label, unit = _split_unit(key)
        dim, factor = UNITS[unit] if unit else ("1", 1.0)
        target = spreads if label == "spread" else values
        matching = [k for k, u in enumerate(units) if u == dim]
        if not matching and lenient:
            continue
        if not matching:
            raise InputError(f"{where}.{key}: no parameter of {name} is in {dim} "
                             f"(its units: {', '.join(sorted(set(units)))})")
        if label != "spread":  # a label that names parameters (base_mm, j2_deg) also selects
            named = [k for k in matching if _selected(subs[k], label)]
            matching = named or matching
        if isinstance(value, dict):
            for selector, v in value.items():
                hit = [k for k in matching if _selected(subs[k], selector)]
                if not hit:
                    raise InputError(f"{where}.{key}: {selector!r} selects no {dim} parameter "
                                     f"(parameters: {', '.join(subs)})")
                target[hit] = _number(v, f"{where}.{key}.{selector}") * factor
        else:
            target[matching] = _number(value, f"{where}.{key}") * factor
    if np.any(spreads < 0):
        raise InputError(f"{where}: spreads must be >= 0")
    if name in NON_NEGATIVE and np.any(values < 0):
        raise InputError(f"{where}: {name} parameters cannot be negative")
    draw = np.isnan(values)
    if np.all(draw) and np.all(np.isnan(spreads)):
        spreads = effect.parameter_scales()  # no values at all: around the typical scales
    spreads = np.where(np.isnan(spreads), 0.0, spreads)
    drawn = spreads[draw] * rng.standard_normal(int(draw.sum()))
    values[draw] = np.abs(drawn) if name in NON_NEGATIVE else drawn + 0.0  # no -0.0
    return effect, values, tcp_rms


# ---------------------------------------------------------------------------------------
# Sampling poses and context
# ---------------------------------------------------------------------------------------
def joint_bounds(robot: RobotModel, span: float = math.pi) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) sampling bounds: the limits, unbounded joints within +-span."""
    lo = np.where(np.isnan(robot.lower_limits), -span, robot.lower_limits)
    hi = np.where(np.isnan(robot.upper_limits), span, robot.upper_limits)
    return lo, hi


def sample_poses(robot: RobotModel, n: int, rng: np.random.Generator, box=None) -> np.ndarray:
    """(n, n_joints) joint values uniform within the limits.

    box : array-like of shape (3, 2), optional
        [[xmin, xmax], [ymin, ymax], [zmin, zmax]] [m]: keep only poses whose nominal
        TCP lies inside (rejection sampling).
    """
    lo, hi = joint_bounds(robot)
    if box is None:
        return rng.uniform(lo, hi, size=(n, robot.n_joints))
    box = np.asarray(box, dtype=float)
    if box.shape != (3, 2) or np.any(box[:, 0] >= box[:, 1]):
        raise InputError("task box: give xmin xmax ymin ymax zmin zmax with min < max")
    kept, tried = [], 0
    batch = max(4 * n, 2000)
    while sum(len(k) for k in kept) < n and tried < 200 * batch:
        q = rng.uniform(lo, hi, size=(batch, robot.n_joints))
        p = tcp_poses(robot, q).position
        inside = np.all((p >= box[:, 0]) & (p <= box[:, 1]), axis=1)
        kept.append(q[inside])
        tried += batch
    found = sum(len(k) for k in kept)
    if found < n:
        raise InputError(f"task box: only {found} of {tried} random poses put the TCP inside it; "
                         f"need {n} (is the box within reach?)")
    return np.concatenate(kept)[:n]


def draw_context(robot: RobotModel, spec: ContextSpec, n: int, rng: np.random.Generator) -> MeasurementContext:
    """Per-row payload, temperature and approach directions as the spec says."""
    payload_mass = typical_payload_kg(robot) if spec.payload_kg is None else float(spec.payload_kg)
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
def _signature(robot, effect, params, q, context) -> np.ndarray:
    """(N, 3) TCP displacement the effect alone causes [m]."""
    nominal = tcp_poses(robot, q).position
    return predict_poses(robot, [effect], [params], q, context).position - nominal


def simulate_measurements(robot: RobotModel, scenario: Scenario | dict, n: int, rng: np.random.Generator,
                          noise_m: float | None = None, *, q: np.ndarray | None = None,
                          context: MeasurementContext | None = None, box=None, orientation: bool = False,
                          orientation_noise_rad: float = DEFAULT_ORIENTATION_NOISE_RAD,
                          ) -> tuple[MeasurementSet, dict]:
    """Measurements of the robot with the scenario's hidden effects.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot (its model is never changed).
    scenario : Scenario or dict
        Hidden effects (see the module docstring); a dict is read as the YAML would be.
    n : int
        Number of measurements (ignored when q is given).
    rng : numpy.random.Generator
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

    Returns
    -------
    (MeasurementSet, truth): truth is a JSON-ready dict of the hidden effects and their
    parameters [SI], the noise, and the context settings.
    """
    if isinstance(scenario, dict):
        scenario = scenario_from_dict(scenario)
    if q is None:
        if n < 1:
            raise InputError(f"--n {n}: need at least one measurement")
        q = sample_poses(robot, n, rng, box)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = q.shape[0]
    if context is None:
        context = draw_context(robot, scenario.context, n, rng)
    elif context.rng is None:
        context = MeasurementContext(context.payload_kg, context.temperature_c, context.direction, rng)
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
        hidden.append(HiddenEffect(effect, params, name in EFFECTS))
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


def truth_as_scenario(truth: dict) -> dict:
    """A scenario dict that re-creates the truth's effects exactly (parameters in SI)."""
    effects = {}
    for name, spec in truth["effects"].items():
        entry = {"parameters": dict(spec["parameters"])}
        if spec.get("options"):
            entry["options"] = dict(spec["options"])
        effects[name] = entry
    return {"effects": effects, "context": dict(truth["context"]), "noise_m": truth["noise_m"]}


# ---------------------------------------------------------------------------------------
# Random scenarios for blind benchmarks
# ---------------------------------------------------------------------------------------
def random_scenario(robot: RobotModel, rng: np.random.Generator, dominant: list[str] | None = None, *,
                    n_dominant: int | None = None, outside: str | None = None, clearance: bool = False,
                    dominance: float = 3.0, noise_m: float = DEFAULT_NOISE_M) -> dict:
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
    dominant : list of str, optional
        Effects to make dominant; default one or two drawn from DOMINANT_CANDIDATES.
    n_dominant : int, optional
        How many to draw when dominant is None (default 1 or 2 at random).
    outside : str, optional
        Also hide an effect outside the vocabulary (``unmodelled`` or ``link_bending``),
        about as large as the dominant effect.
    clearance : bool
        Add joint clearance (a few hundredths of a mm of scatter).

    Returns
    -------
    dict: a scenario with explicit SI parameters, plus ``dominant`` (ordered, largest
    first) and ``notes``.
    """
    if dominant is None:
        k = n_dominant if n_dominant is not None else int(rng.integers(1, 3))
        dominant = list(rng.choice(DOMINANT_CANDIDATES, size=k, replace=False))
    for name in dominant:
        if name not in EFFECTS or name in ("frames", "clearance"):
            raise InputError(f"dominant effect {name!r}: choose from {', '.join(DOMINANT_CANDIDATES)}")
    if outside is not None and outside not in OUTSIDE_VOCABULARY:
        raise InputError(f"outside effect {outside!r}: choose from {', '.join(OUTSIDE_VOCABULARY)}")
    deg = math.pi / 180.0
    u = rng.uniform
    specs: dict[str, dict] = {
        "frames": {"spread_mm": {"base": 20.0, "tool": 1.0}, "spread_mrad": {"base": 5.0}},
        "geometry": {"spread_mm": u(0.1, 0.5), "spread_mrad": u(0.1, 0.5)},
        "joint_offsets": {"spread_deg": u(0.01, 0.05), "spread_mm": u(0.01, 0.05)},
    }
    for name in dominant:
        if name == "compliance":
            # each joint turned by a similar angle under its typical torque, then scaled
            pattern = EFFECTS["compliance"](robot).parameter_scales() * np.exp(0.5 * rng.standard_normal(robot.n_joints))
            specs[name] = {"parameters": {f"compliance.{j}": float(c) for j, c in zip(robot.joint_names, pattern)},
                           "tcp_rms_mm": u(0.5, 3.0), "options": {"link_mass_spread": 0.05}}
        elif name == "backlash":
            specs[name] = {"backlash_deg": float(u(0.01, 0.05)), "backlash_mm": float(u(0.01, 0.05))}
        elif name == "thermal":
            specs[name] = {"alpha_per_k": float(u(1.0e-5, 2.4e-5))}
        elif name == "transmission":
            specs[name] = {"spread_deg": float(u(0.005, 0.02))}
        elif name == "encoder_scale":
            specs[name] = {"spread_ppm": float(u(100.0, 500.0))}
    if clearance:
        specs["clearance"] = {"axial_mm": 0.005, "radial_mm": 0.005, "tilt_mrad": 0.005}
    context = {"payload_fraction": 0.5, "temperature_spread_c": 10.0, "directions": "random"}

    # resolve to explicit SI values on reference rows, then enforce dominance
    ref_rng = np.random.default_rng(rng.integers(2**63))
    q_ref = sample_poses(robot, 400, ref_rng)
    ctx_ref = draw_context(robot, ContextSpec(**context), 400, ref_rng)
    resolved = {}
    for name, spec in specs.items():
        effect, params, tcp_rms = resolve_effect(robot, name, spec, rng, "random_scenario", lenient=True)
        if name == "backlash":  # one band width per joint, drawn in the range, not a single value
            lo_hi = np.where(np.array(effect.parameter_units()) == "rad", deg, 1e-3)
            params = lo_hi * u(0.01, 0.05, size=effect.n_params)
        if name == "encoder_scale":
            params = rng.choice([-1.0, 1.0], effect.n_params) * u(1e-4, 5e-4, size=effect.n_params)
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
        shrink = max(1.0 / need, 0.2)
        for name in ("geometry", "joint_offsets"):
            resolved[name] = (resolved[name][0], resolved[name][1] * shrink)
        notes["background_factor"] = shrink
        grow = need * shrink
        if grow > 1.0:
            for name in dominant:
                resolved[name] = (resolved[name][0], resolved[name][1] * grow)
            notes["dominant_factor"] = grow
    if outside is not None:
        effect = OUTSIDE_VOCABULARY[outside](robot)
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
        "notes": {k: float(v) for k, v in notes.items()},
    }
    return scenario


def write_truth(path: str | Path, truth: dict) -> None:
    """Write the hidden truth as YAML (.yaml/.yml) or JSON (anything else), atomically."""
    import json

    import yaml

    from .atomic import write_text_atomically

    path = Path(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        text = yaml.safe_dump(truth, sort_keys=False)
    else:
        text = json.dumps(truth, indent=2, allow_nan=False) + "\n"
    write_text_atomically(path, text)
