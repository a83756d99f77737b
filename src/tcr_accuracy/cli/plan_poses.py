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

from .common import (add_reach_arguments, add_robot_arguments, effect_names, emit_json, integer, noise_mm_value,
                     number, output_file, reach_values, seed_value)


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "plan-poses", help="choose the next poses to measure (separates what the diagnosis cannot tell apart)",
        description="Diagnose the measured poses; where the diagnosis reports effects it cannot tell apart, "
                    "choose K joint configurations (random within the joint limits, <mimic> rules kept, free of "
                    "self-collision where the URDF has collision geometry, optionally with the TCP in a task box "
                    "and in the tracker's line of sight; or from a candidate CSV) where "
                    "the rival fitted models disagree by more than either can fit away (greedy T-optimal "
                    "design); otherwise (or with --effects) those that add the most information about all "
                    "the parameters together (greedy D-optimal design on the identification Jacobian). "
                    "Writes them as a CSV of joint values (deg, mm) to measure.",
    )
    p.add_argument("measurements", metavar="MEASUREMENTS.csv", help="the measurements so far (see README)")
    add_robot_arguments(p)
    p.add_argument("-k", "--poses", type=integer(low=1, high=100_000), default=30,
                   help="how many poses to suggest (default 30)")
    p.add_argument("--out", required=True, type=output_file, metavar="FILE.csv",
                   help="where to write the suggested poses")
    p.add_argument("--effects", default=None, metavar="LIST",
                   help="comma-separated effects to design for (default: diagnose the measurements and take "
                        "the chosen effects and their ambiguity groups)")
    p.add_argument("--candidates", default=None, metavar="FILE.csv",
                   help="choose among these joint configurations (a CSV with the robot's joint columns, "
                        "e.g. the reachable poses of a task); default: uniform within the joint limits")
    p.add_argument("--n-candidates", type=integer(low=1, high=1_000_000), default=3000,
                   help="random candidates when --candidates is not given (default 3000)")
    add_reach_arguments(p, "candidates")
    p.add_argument("--payload-kg", type=number(low=0, high=1e6, unit="kg"), default=None,
                   help="payload the new poses will be measured with [kg] (default: the measurements' mean)")
    p.add_argument("--noise-mm", type=noise_mm_value, default=None,
                   help="the instrument's noise, std per axis [mm], for the diagnosis and for counting the "
                        "determined parameter combinations (default: the diagnosis' estimate; 0.02 with --effects)")
    p.add_argument("--seed", type=seed_value, default=0, help="seed of the candidates and of the diagnosis")
    p.add_argument("--json", default=None, type=output_file, metavar="FILE",
                   help="also write the plan as JSON ('-' for stdout)")
    p.set_defaults(run=_run_plan_poses)


def _check(args) -> None:
    """What the options' types cannot check alone."""
    from ..exceptions import InputError

    if args.n_candidates < args.poses:
        raise InputError(f"--n-candidates {args.n_candidates}: need at least -k ({args.poses})")
    reach_values(args)  # the box, checked before the diagnosis


#: Memory [bytes] planning takes per candidate configuration: its 3 x P Jacobian block over the
#: whole vocabulary (P up to about 130 columns) and a few working copies, generously.
PLAN_CANDIDATE_BYTES = 3 * 130 * 8 * 8


def _check_plan_memory(args) -> None:
    """Refuse before the work a plan whose measurements (diagnosed first), candidate file or
    --n-candidates would need more memory than ``--max-memory-gb``."""
    from .common import check_csv_memory, check_memory
    from .diagnose import DIAGNOSE_ROW_BYTES

    check_csv_memory(args, args.measurements, "planning poses from", DIAGNOSE_ROW_BYTES)
    if args.candidates:
        check_csv_memory(args, args.candidates, "planning poses among", PLAN_CANDIDATE_BYTES,
                         hint="use fewer candidates")
    else:
        check_memory(args, f"--n-candidates {args.n_candidates}", args.n_candidates * PLAN_CANDIDATE_BYTES,
                     "use fewer candidates")


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


def _run_plan_poses(args) -> int:
    import numpy as np

    from .staging import write_text
    from ..diagnosis.design import plan_discriminating_poses, plan_poses, separating_order
    from ..diagnosis.ambiguity import rival_models
    from ..diagnosis.diagnose import GapDiagnosis
    from ..io.measurements import read_measurements
    from .common import robot_from_args

    _check(args)
    _check_plan_memory(args)
    robot = robot_from_args(args)
    measured = read_measurements(args.measurements, robot)
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
        payload = float(np.mean(measured.payload_kg)) if measured.payload_kg is not None else 0.0
    groups, separate, pairs, confounding = [], None, [], []
    noise_m = 2e-5 if args.noise_mm is None else args.noise_mm * 1e-3
    effects = effect_names(args.effects)
    if effects is None:
        estimator = GapDiagnosis(robot=robot, random_state=args.seed, tracker_noise=None if args.noise_mm is None
                                 else args.noise_mm * 1e-3).fit(measured)
        result = estimator.result_
        groups = [g["effects"] for g in result.ambiguous]
        noise_m = result.tracker_noise
        rivals = {name for group in result.ambiguous for member in group["members"] for name in member["effects"]}
        effects = sorted(set(result.selected_effects) | rivals)
        separate = sorted(rivals) or None
        pairs = rival_models(estimator) if separate else []
        confounding = [c.to_dict() for c in result.stages.attribute.confounding]
    if pairs:  # rival fitted models: the poses where they differ beyond refitting (T-optimal)
        candidates = plan_discriminating_poses(robot, measured.q, pairs, k, candidates=candidates,
                                               n_candidates=args.n_candidates, payload_kg=payload,
                                               rng=np.random.default_rng(args.seed))
    # D-optimal otherwise; with rivals, over exactly the poses picked above (for its figures)
    plan = plan_poses(robot, measured.q, effects, k, separate=separate, candidates=candidates,
                      n_candidates=args.n_candidates, payload_kg=payload, noise_m=noise_m,
                      rng=np.random.default_rng(args.seed))
    # measured in this order, no joint follows time: a drift cannot pass for an error growing with a joint
    order, largest_r = separating_order(plan.q, np.random.default_rng([args.seed, 3]))
    plan_q = plan.q[order]
    write_text(Path(args.out), _plan_csv(robot, plan_q, args, plan.effects, pose_filter.checks))
    summary = {"measurements": str(args.measurements), "n_measured": len(measured), "k": k,
               "candidates": {"source": source, "tried": screened.tried, "kept": len(screened.q),
                              "rejected": {reason.replace(" ", "_").replace("-", "_"): n
                                           for reason, n in screened.rejected.items()},
                              "checks": pose_filter.checks},
               "design": "T-optimal between rival fitted models" if pairs else "D-optimal",
               "effects": plan.effects, "separate": plan.separate, "ambiguous": groups,
               "n_parameters": plan.n_parameters, "log_det_gain": plan.log_det_gain,
               "resolved_before": plan.resolved_before, "resolved_after": plan.resolved_after,
               "payload_kg": payload, "out": str(args.out), "q_display": (plan_q * robot.display_scale).tolist(),
               "order_largest_abs_r": largest_r, "confounding": confounding}
    if args.json:
        emit_json(summary, args.json)
    if args.json != "-":
        print(candidates_line)
        print(f"designed for: {', '.join(plan.effects)} ({plan.n_parameters} parameters); "
              + (f"to tell apart {', '.join(plan.separate)}: where the rival fitted models differ beyond refitting "
                 "(T-optimal)" if pairs else "D-optimal"))
        for group in groups:
            print(f"  the measurements cannot tell apart: {{{', '.join(group)}}}")
        print(f"{k} poses chosen: information log det +{plan.log_det_gain:.1f}; parameter combinations "
              f"determined to better than their typical size: {plan.resolved_before} -> {plan.resolved_after} "
              f"of {plan.n_parameters}")
        for c in confounding:
            print(f"  the measurements' order: {c['why']}")
        print(f"written: {args.out}, in an order to measure them in: no joint follows it (largest |r| with the "
              f"row's place {largest_r:.2f}), so a drift in time cannot pass for an error growing with a joint")
    return 0


def _plan_csv(robot, q, args, effects, checks) -> str:
    """Joint values in deg / mm, one pose per row, with a comment on how they were chosen."""
    import io

    units = {"revolute": "deg", "prismatic": "mm"}
    header = [f"{n}_{units.get(k, 'mm')}" for n, k in zip(robot.joint_names, robot.joint_kinds)]
    out = io.StringIO()
    out.write(f"# {len(q)} poses to measure next, chosen by tcr-accuracy plan-poses from {args.measurements}\n")
    out.write(f"# (D-optimal for {', '.join(effects)}); add the measured x_mm,y_mm,z_mm columns and diagnose "
              "both files together\n")
    out.write(f"# candidates: {checks}\n")
    out.write(",".join(header) + "\n")
    for row in q * robot.display_scale:
        out.write(",".join(format(v, ".10g") for v in row) + "\n")
    return out.getvalue()
