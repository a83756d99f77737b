"""``tcr-accuracy plan-poses``: which poses to measure next so that the diagnosis can tell
apart what the measured ones cannot.

Edge layer: reads the measurement CSV, runs the diagnosis (unless ``--effects`` names what
to design for), runs :func:`tcr_accuracy.diagnosis.design.plan_poses`, prints what the
plan adds and writes the poses as a CSV of joint values (deg, mm) ready to measure. The
candidates are poses the robot can take and the tracker can see, screened by
:class:`tcr_accuracy.analysis.reachable.PoseFilter` (the filter ``simulate`` uses too).
"""

from __future__ import annotations

from pathlib import Path

from .common import (MAX_MM, add_quiet_argument, add_reach_arguments, add_robot_arguments, effect_names, emit_json,
                     integer, noise_mm_value, number, output_file, output_file_only, reach_values, seed_value)


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "plan-poses", help="choose the next poses to measure, for the prediction where the robot works",
        description="Choose K joint configurations to measure (among poses the robot can take and the tracker "
                    "can see: random within the joint limits, <mimic> rules kept, free of self-collision where the "
                    "URDF has collision geometry, optionally with the TCP in a task box and in the tracker's line "
                    "of sight; or from a candidate CSV) that best predict the error where the robot will work "
                    "(--targets, the box, or the joint ranges): a Bayesian I-optimal design on the linearised "
                    "effect vocabulary, each effect's parameters at their typical sizes (scaled to what the "
                    "measurements so far show, when given). G- and D-optimal on request; T-optimal tells apart "
                    "the rival models a diagnosis of the measurements cannot. With measurements, also the "
                    "learning curve (held-out error against the number of poses) and whether measuring more "
                    "is worth it. Writes the poses, in an order to measure them in, as a CSV of joint values "
                    "(deg, mm).",
    )
    p.add_argument("measurements", metavar="MEASUREMENTS.csv", nargs="*",
                   help="the measurements so far (see docs/measurements.md; several files share one tracker frame); none: a "
                        "first campaign, designed for the effect vocabulary at typical sizes")
    add_robot_arguments(p)
    p.add_argument("-k", "--poses", type=integer(low=1, high=100_000), default=30,
                   help="how many poses to suggest (default 30)")
    p.add_argument("--out", required=True, type=output_file_only, metavar="FILE.csv",
                   help="where to write the suggested poses")
    p.add_argument("--design", default="I", choices=("I", "G", "D", "T"),
                   help="I: least prediction variance averaged over the task (default); G: least largest "
                        "prediction variance over the task; D: most information on all parameters; T: where the "
                        "rival models a diagnosis of the measurements cannot tell apart differ most")
    p.add_argument("--targets", default=None, metavar="FILE.csv",
                   help="where the robot will work: its joint values (a CSV with the robot's joint columns), the "
                        "poses the design predicts best (default: the candidates)")
    p.add_argument("--effects", default=None, metavar="LIST",
                   help="comma-separated effects to design for (default: every effect the joint values drive; "
                        "with --design T, the diagnosis' chosen effects and their ambiguity groups)")
    p.add_argument("--candidates", default=None, metavar="FILE.csv",
                   help="choose among these joint configurations (a CSV with the robot's joint columns, "
                        "e.g. the reachable poses of a task); default: uniform within the joint limits")
    p.add_argument("--n-candidates", type=integer(low=1, high=1_000_000), default=3000,
                   help="random candidates when --candidates is not given (default 3000)")
    add_reach_arguments(p, "candidates")
    p.add_argument("--payload-kg", type=number(low=0, high=1e6, unit="kg"), default=None,
                   help="payload the new poses will be measured with [kg] (default: the measurements' mean)")
    p.add_argument("--noise-mm", type=noise_mm_value, default=None,
                   help="the instrument's noise, std per axis [mm] (default: fitted to the measurements; 0.02 "
                        "without)")
    p.add_argument("--references", type=integer(low=0, high=1000), default=None,
                   help="times a reference pose is measured through the campaign (first, last, evenly between) to "
                        "see drift and repeatability (default 1 + K // 20; 0: none)")
    p.add_argument("--stop-gain-mm", type=number(low=0, high=MAX_MM, unit="mm"), default=None,
                   help="with measurements: advise to stop when measuring K more poses is expected to lower the "
                        "held-out RMS error by less than this [mm] (the noise floor stops it anyway)")
    p.add_argument("--seed", type=seed_value, default=0, help="seed of the candidates, the order and the curve")
    p.add_argument("--json", default=None, type=output_file, metavar="FILE",
                   help="also write the plan as JSON ('-' for stdout)")
    add_quiet_argument(p)
    p.set_defaults(run=_run_plan_poses)


def _check(args) -> None:
    """What the options' types cannot check alone."""
    from ..exceptions import InputError

    if args.n_candidates < args.poses and not args.candidates:
        raise InputError(f"--n-candidates {args.n_candidates}: need at least -k ({args.poses})")
    if args.design == "T" and not args.measurements:
        raise InputError("--design T: tells apart the rival models a diagnosis of measurements cannot; give the "
                         "MEASUREMENTS.csv (a first campaign takes --design I, G or D)")
    if args.stop_gain_mm is not None and not args.measurements:
        raise InputError("--stop-gain-mm: the stop rule reads the learning curve of measurements; give the "
                         "MEASUREMENTS.csv")
    reach_values(args)  # the box, checked before the work


#: Memory [bytes] planning takes per candidate configuration: its 3 x P block over the design
#: vocabulary (P up to about 520 columns on a 6-joint arm with the cyclic series) and three working
#: copies of it (the scaled block, the posterior's H = w S, a product with W).
PLAN_CANDIDATE_BYTES = 3 * 520 * 8 * 4


def _check_plan_memory(args) -> None:
    """Refuse before the work a plan whose measurements, candidate file or --n-candidates would need more
    memory than ``--max-memory-gb``."""
    from .common import check_csv_memory, check_memory
    from .diagnose import DIAGNOSE_ROW_BYTES

    for path in args.measurements:
        check_csv_memory(args, path, "planning poses from", DIAGNOSE_ROW_BYTES if args.design == "T"
                         else PLAN_CANDIDATE_BYTES)
    if args.candidates:
        check_csv_memory(args, args.candidates, "planning poses among", PLAN_CANDIDATE_BYTES,
                         hint="use fewer candidates")
    else:
        check_memory(args, f"--n-candidates {args.n_candidates}", args.n_candidates * PLAN_CANDIDATE_BYTES,
                     "use fewer candidates")
    if args.targets:
        check_csv_memory(args, args.targets, "planning poses for", PLAN_CANDIDATE_BYTES, hint="use fewer targets")


def _reachable_candidates(args, robot, read_measurements):
    """The candidates (M, n_joints) [SI] and what screened them: the ``--candidates`` file, a row
    the robot cannot take (outside its limits, off a <mimic> rule) refused by name, or
    ``--n-candidates`` random poses; either kept where the robot can take them (self-collision)
    and, when asked, the TCP is in the box and in the tracker's sight.

    Raises
    ------
    InputError
        A row of the file the robot cannot take, or no candidate left.
    """
    import warnings

    import numpy as np

    from ..analysis.reachable import PoseFilter, Screened, check_given_poses, draw_poses
    from ..exceptions import InputError
    from ..io.measurement_checks import MeasurementWarning
    from ..model.robot import JointLimitWarning

    box, tracker = reach_values(args)
    pose_filter = PoseFilter.for_robot(robot, box=box, tracker=tracker)
    if args.candidates:
        with warnings.catch_warnings():  # limits are refused below, by row
            warnings.simplefilter("ignore", JointLimitWarning)
            warnings.simplefilter("ignore", MeasurementWarning)
            mset = read_measurements(args.candidates, robot, require_position=False)
        check_given_poses(robot, mset.q, args.candidates, mset.rows)
        keep, rejected = pose_filter.screen(mset.q)
        screened, source = Screened(mset.q[keep], len(mset.q), rejected), f"from {args.candidates}"
    else:
        screened, source = draw_poses(pose_filter, args.n_candidates, np.random.default_rng(args.seed)), "random"
    if len(screened.q) == 0:
        raise InputError(f"no candidate left: of {screened.tried} {source}, {screened.rejections()}; "
                         + ("widen --box or move --tracker-mm" if box is not None or tracker is not None
                            else "give other candidates"))
    return screened, source, pose_filter


def _read_measured(args, robot):
    """The measurements (one set; several files joined, one tracker frame), or None for a first campaign."""
    from ..io.measurement_set import join_sessions
    from ..io.measurements import read_measurements

    if not args.measurements:
        return None
    sets = [read_measurements(path, robot) for path in args.measurements]
    return join_sessions(sets, [str(path) for path in args.measurements])


def _targets(args, robot):
    """The task poses (T, n_joints) [SI] of ``--targets`` (refused by row where the robot cannot take one), or None."""
    import warnings

    from ..analysis.reachable import check_given_poses
    from ..io.measurement_checks import MeasurementWarning
    from ..io.measurements import read_measurements
    from ..model.robot import JointLimitWarning

    if not args.targets:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", JointLimitWarning)
        warnings.simplefilter("ignore", MeasurementWarning)
        mset = read_measurements(args.targets, robot, require_position=False, repeats_allowed=True)
    check_given_poses(robot, mset.q, args.targets, mset.rows)
    return mset.q


def _run_plan_poses(args) -> int:
    import numpy as np

    from ..io.measurements import read_measurements
    from .common import robot_from_args
    from .output import progress_bar

    _check(args)
    _check_plan_memory(args)
    robot = robot_from_args(args)
    measured = _read_measured(args, robot)
    task_q = _targets(args, robot)
    screened, source, pose_filter = _reachable_candidates(args, robot, read_measurements)
    candidates, k = screened.q, min(args.poses, len(screened.q))
    tried = (f" ({screened.tried} {'given' if args.candidates else 'drawn'}: {screened.rejections()})"
             if screened.tried > len(candidates) else "")
    if k < args.poses or (not args.candidates and len(candidates) < args.n_candidates):
        candidates_line = (f"only {len(candidates)} candidates ({source}) survive{tried}: "
                           + (f"planning {k} poses instead of {args.poses}; " if k < args.poses else "")
                           + pose_filter.checks)
    else:
        candidates_line = f"candidates: {len(candidates)} {source}, {pose_filter.checks}{tried}"
    payload = args.payload_kg
    if payload is None:
        payload = float(np.mean(measured.payload_kg)) if measured is not None and measured.payload_kg is not None \
            else 0.0
    n_refs = 1 + k // 20 if args.references is None else args.references
    curve_steps = 5 if args.design != "T" and measured is not None and len(measured) >= 20 else 0
    update, close = progress_bar(k + curve_steps, "plan-poses", args.quiet)
    try:
        if args.design == "T":
            plan = _plan_t_optimal(args, robot, measured, candidates, k, payload, update)
        else:
            plan = _plan_for_prediction(args, robot, measured, candidates, task_q, k, payload, update)
    finally:
        close()
    rows, reference, largest_r = _order(plan["q"], n_refs, args.seed)
    plan_q = plan["q"][rows]
    pose_ids = [("R" if i == reference and n_refs > 1 else f"P{i + 1:02d}") for i in rows]
    _write_plan(args, robot, plan_q, pose_ids, plan["headline"], pose_filter.checks)
    summary = {"measurements": [str(m) for m in args.measurements], "n_measured": 0 if measured is None
               else len(measured), "k": k, "design": plan["design"],
               "candidates": {"source": source, "tried": screened.tried, "kept": len(screened.q),
                              "rejected": {reason.replace(" ", "_").replace("-", "_"): n
                                           for reason, n in screened.rejected.items()},
                              "checks": pose_filter.checks},
               "payload_kg": payload, "out": str(args.out), "pose_id": pose_ids,
               "q_display": (plan_q * robot.display_scale).tolist(), "reference_repeats": n_refs if n_refs > 1 else 0,
               "order_largest_abs_r": largest_r, **plan["json"]}
    if args.json:
        emit_json(summary, args.json)
    if args.json != "-":
        print(candidates_line)
        for line in plan["lines"]:
            print(line)
        print(_next_step(args, k, n_refs, largest_r, plan))
    return 0


def _order(q, n_refs: int, seed: int):
    """The measuring order (rows into q, the reference repeated), the reference's index and the largest |r|."""
    import numpy as np

    from ..diagnosis.bayes_design import campaign_order

    return campaign_order(q, n_refs, np.random.default_rng([seed, 3]))


def _next_step(args, k: int, n_refs: int, largest_r: float, plan: dict) -> str:
    """What to do with the file: the line a person acts on."""
    import shlex

    measured = " ".join(shlex.quote(str(m)) for m in args.measurements)
    robot = (f" --robot {shlex.quote(str(args.robot))}" if args.robot else "") + \
        (f" --tool {shlex.quote(args.tool)}" if args.tool else "")
    refs = (f"; the reference pose R {n_refs} times (first, last and evenly between: drift and repeatability)"
            if n_refs > 1 else "")
    stop = plan.get("stop")
    head = "if you go on: " if stop else "next: "
    then = (f"tcr-accuracy plan-poses {(measured + ' ') if measured else ''}{Path(args.out).stem}_measured.csv{robot} "
            f"-k {k} --out next.csv" + (f" --stop-gain-mm {args.stop_gain_mm:g}" if args.stop_gain_mm is not None
                                        else ""))
    return (f"{head}measure the {k} poses of {args.out} in its order (no joint follows the order: largest |r| "
            f"{largest_r:.2f}, so a drift cannot pass for an error growing with a joint{refs}); add the measured "
            f"x_mm, y_mm, z_mm columns (as {Path(args.out).stem}_measured.csv), then run `tcr-accuracy diagnose "
            f"{(measured + ' ') if measured else ''}{Path(args.out).stem}_measured.csv{robot}` and, for "
            f"the next batch, `{then}`")


def _plan_for_prediction(args, robot, measured, candidates, task_q, k, payload, update) -> dict:
    """The I-, G- or D-optimal design on the effect vocabulary, the prior from the measurements, and the curve."""
    import numpy as np

    from ..diagnosis.bayes_design import (LEARNING_CURVE_MIN_POSES, design_columns, design_vocabulary, fit_prior,
                                          learning_curve, nonzero_effects, plan_design, stop_advice, typical_prior)
    from ..exceptions import InputError

    effects = design_vocabulary(effect_names(args.effects))
    if not effects:
        raise InputError(f"--effects {args.effects}: none of them is driven by the joint values alone (drift, "
                         "thermal and backlash read time, temperature and direction: the order handles drift)")
    cand = design_columns(robot, candidates, effects, payload_kg=payload)
    effects = nonzero_effects(cand)
    cand = design_columns(robot, candidates, effects, payload_kg=payload) if len(effects) < len(cand.effects) \
        else cand
    task = cand if task_q is None else design_columns(robot, task_q, effects, payload_kg=payload)
    noise_m = None if args.noise_mm is None else args.noise_mm * 1e-3
    lines, out = [], {}
    measured_columns = errors = None
    if measured is None:
        prior = typical_prior(effects, noise_m)
        prior_words = (f"prior: every effect at its typical size, noise {prior.noise_m * 1e3:.4g} mm per axis"
                       + (" (--noise-mm)" if noise_m is not None else " (a laser tracker; --noise-mm to change)"))
    else:
        from ..frames.registration import register_tracker
        from ..model.kinematics import tcp_poses

        context = measured.context if hasattr(measured, "context") else None
        registration = register_tracker(robot, measured.q, measured.position, context=context)
        errors = registration.to_base(measured.position) - tcp_poses(robot, measured.q).position
        measured_columns = design_columns(robot, measured.q, effects, payload_kg=payload)
        prior = fit_prior(measured_columns, errors, noise_m=noise_m)
        sizes = ", ".join(f"{e} {t:.2g}" for e, t in prior.tau.items())
        prior_words = (f"prior fitted to the {len(measured)} measured poses (type-II maximum likelihood): noise "
                       f"{prior.noise_m * 1e3:.4f} mm per axis{' (--noise-mm)' if noise_m is not None else ''} "
                       "(with what the vocabulary leaves); " + (f"typical sizes x {sizes}; " if sizes else "")
                       + "geometric effects free")
    names = {"I": "I-optimal: least prediction variance averaged over", "G": "G-optimal: least largest prediction "
             "variance over", "D": "D-optimal: most information on all parameters; variance reported over"}
    where = f"the {len(task_q)} --targets poses" if task_q is not None else f"the {len(candidates)} candidates"
    design = plan_design(measured_columns, cand, task, prior, k, criterion=args.design,
                         rng=np.random.default_rng([args.seed, 5]), progress=update)
    headline = f"{names[args.design].split(':')[0]} for the prediction over {where}"
    lines.append(f"design: {names[args.design]} {where}; effects {', '.join(effects)} ({cand.n_parameters} "
                 "parameters, linearised at the nominal robot)")
    lines.append(f"  {prior_words}")
    after = (f"{design.task_std_after_m * 1e3:.4f} mm; {design.task_worst_std_after_m * 1e3:.4f} mm with the {k} "
             f"poses (information log det +{design.log_det_gain:.1f})")
    lines.append("  prediction std over the task (3D, RMS; largest): " + (
        f"{design.task_std_before_m * 1e3:.4f} mm; {design.task_worst_std_before_m * 1e3:.4f} mm now -> {after}"
        if measured is not None else f"{after} (nothing is known of the geometry before them)"))
    out.update({"effects": effects, "n_parameters": cand.n_parameters, "prior": prior.to_dict(),
                "task": {"source": "targets" if task_q is not None else "candidates", "n": int(task.g.shape[0])},
                "task_std_mm": {"before": design.task_std_before_m * 1e3, "after": design.task_std_after_m * 1e3,
                                "worst_before": design.task_worst_std_before_m * 1e3,
                                "worst_after": design.task_worst_std_after_m * 1e3},
                "log_det_gain": design.log_det_gain})
    plan = {"q": candidates[design.picked], "design": f"{args.design}-optimal (Bayesian)", "headline": headline,
            "lines": lines, "json": out}
    if measured is not None:
        if len(measured) < LEARNING_CURVE_MIN_POSES:
            lines.append(f"learning curve: not drawn ({len(measured)} measured poses; it needs "
                         f"{LEARNING_CURVE_MIN_POSES})")
        else:
            curve = learning_curve(measured_columns, errors, prior, np.random.default_rng([args.seed, 7]),
                                   progress=update)
            advice = stop_advice(curve, design, min_gain_m=None if args.stop_gain_mm is None
                                 else args.stop_gain_mm * 1e-3)
            lines.append("learning curve (held-out RMS of the 3D miss of the linearised vocabulary with this prior, "
                         "fitted on subsamples of the measured poses and scored on the rest, 5-95 % over 8 "
                         "subsamples; what the model expects there):")
            for n, rms, low, high, model in zip(curve.sizes, curve.rms_m, curve.low_m, curve.high_m,
                                                curve.expected_rms_m):
                lines.append(f"  {n:5d} poses  {rms * 1e3:.4f} mm  [{low * 1e3:.4f}, {high * 1e3:.4f}]  expected "
                             f"{model * 1e3:.4f} mm")
            lines.append(f"  the misses show {curve.noise_weight:.2f} x the noise and {curve.variance_weight:.2f} x the "
                         "posterior variance the model expects (1 and 1 for a model that is right; the interval "
                         f"below allows for them); noise floor {curve.floor_m * 1e3:.4f} mm (sqrt(3) x the noise "
                         "per axis)")
            lines.append(advice.reason)
            lines.append("to predict with this model (the vocabulary, linearised, with the fitted prior): tcr-accuracy "
                         "predict --method bayes")
            plan["stop"] = advice.stop
            out["learning_curve"] = curve.to_dict()
            out["stop"] = {"stop": advice.stop, "reason": advice.reason,
                           "now_mm": [v * 1e3 for v in advice.now_m], "then_mm": [v * 1e3 for v in advice.then_m],
                           "gain_mm": [v * 1e3 for v in advice.gain_m],
                           "limit_mm": args.stop_gain_mm}
    return plan


def _plan_t_optimal(args, robot, measured, candidates, k, payload, update) -> dict:
    """T-optimal between the rival models a diagnosis of the measurements cannot tell apart."""
    from ..diagnosis.ambiguity import rival_models
    from ..diagnosis.design import plan_discriminating_poses
    from ..diagnosis.diagnose import GapDiagnosis
    from ..exceptions import InputError

    estimator = GapDiagnosis(robot=robot, random_state=args.seed, effects=effect_names(args.effects),
                             tracker_noise=None if args.noise_mm is None else args.noise_mm * 1e-3).fit(measured)
    result = estimator.result_
    groups = [g["effects"] for g in result.ambiguous]
    pairs = rival_models(estimator)
    if not pairs:
        raise InputError(f"--design T: the diagnosis of {', '.join(map(str, args.measurements))} tells every chosen "
                         f"effect apart ({', '.join(result.selected_effects)}): no rival models to separate; "
                         "use --design I")
    q = plan_discriminating_poses(robot, measured.q, pairs, k, candidates=candidates, payload_kg=payload,
                                  noise_m=result.tracker_noise, progress=update)
    confounding = [c.to_dict() for c in result.stages.attribute.confounding]
    lines = [f"design: T-optimal, where the rival fitted models differ beyond refitting ({len(pairs)} pairs)"]
    lines += [f"  the measurements cannot tell apart: {{{', '.join(group)}}}" for group in groups]
    lines += [f"  the measurements' order: {c['why']}" for c in confounding]
    return {"q": q, "design": "T-optimal between rival fitted models", "headline": "T-optimal between rival models",
            "lines": lines, "json": {"ambiguous": groups, "confounding": confounding,
                                     "selected_effects": list(result.selected_effects)}}


def _write_plan(args, robot, q, pose_ids, headline: str, checks: str) -> None:
    """Joint values in deg / mm, one pose per row with its id, and a comment on how they were chosen."""
    import io

    from .staging import write_text

    units = {"revolute": "deg", "prismatic": "mm"}
    header = ["pose_id"] + [f"{n}_{units.get(k, 'mm')}" for n, k in zip(robot.joint_names, robot.joint_kinds)]
    out = io.StringIO()
    source = ", ".join(map(str, args.measurements)) or "nothing measured (a first campaign)"
    out.write(f"# {len(q)} poses to measure in this order, chosen by tcr-accuracy plan-poses from {source}\n")
    out.write(f"# ({headline}); add the measured x_mm,y_mm,z_mm columns and diagnose with the poses measured before\n")
    out.write(f"# candidates: {checks}\n")
    out.write(",".join(header) + "\n")
    for pose_id, row in zip(pose_ids, q * robot.display_scale):
        out.write(pose_id + "," + ",".join(format(v, ".10g") for v in row) + "\n")
    write_text(Path(args.out), out.getvalue())
