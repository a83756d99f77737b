"""``tcr-accuracy simulate``: measurements of a robot with hidden effects (a stand-in robot)."""

from __future__ import annotations

from .common import (EXIT_OK, MAX_COUNT, MAX_MM, add_quiet_argument, add_reach_arguments, add_robot_arguments,
                     check_csv_memory, check_memory, integer, number, output_file, reach_values, sample_bytes,
                     seed_value, status)


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "simulate", help="write a measurement CSV of a robot with hidden effects",
        description="Stand-in for the real robot: perturb the nominal model with the hidden effects "
                    "of a scenario (YAML), take N poses (random within the joint limits, <mimic> rules kept, "
                    "free of self-collision where the URDF has collision geometry, the TCP and the joints above "
                    "the plane the robot stands on, optionally in a task box and in the tracker's line of sight; "
                    "or from --poses), add laser-tracker noise and write "
                    "a measurement CSV. The hidden truth goes to --truth only, never into the CSV.",
    )
    add_robot_arguments(p)
    p.add_argument("--scenario", metavar="YAML", default=None,
                   help="hidden effects (see examples/scenario_*.yaml); without it: --random")
    p.add_argument("--random", nargs="*", metavar="EFFECT", default=None,
                   help="draw a random realistic scenario (geometry plus the named dominant effects, "
                        "or one or two drawn at random)")
    p.add_argument("--outside", metavar="EFFECT", default=None,
                   help="with --random: also hide an effect outside the vocabulary (unmodelled, link_bending)")
    p.add_argument("--n", type=integer(low=1, high=MAX_COUNT), default=None,
                   help="number of measurements (default 200; not with --poses, whose rows are the poses)")
    p.add_argument("--poses", metavar="CSV", default=None,
                   help="commanded poses (joint columns, optional context columns) instead of random ones")
    add_reach_arguments(p, "random poses")
    p.add_argument("--below-mounting-plane", action="store_true",
                   help="also draw random poses that put the TCP or a joint below the plane the robot stands on "
                        "(z = 0 of its base); by default they are drawn again, for every robot but the built-in "
                        "tool-changer, which works below its base inside the cutterhead")
    p.add_argument("--noise-mm", type=number(low=0, high=MAX_MM, unit="mm"), default=None,
                   help="tracker noise, std per axis [mm] (default: the scenario's, else 0.02)")
    p.add_argument("--orientation", action="store_true", help="also write measured orientations (qw..qz)")
    p.add_argument("--seed", type=seed_value, default=0, help="random seed (default 0)")
    p.add_argument("--unit", choices=("mm", "m"), default="mm",
                   help="CSV units: mm (joints in deg/mm) or m (rad/m) (default mm)")
    p.add_argument("--out", required=True, type=output_file, metavar="CSV", help="measurement CSV to write")
    p.add_argument("--truth", type=output_file, metavar="FILE", default=None,
                   help="write the hidden truth here (.yaml/.yml or JSON); keep it from the diagnosis")
    add_quiet_argument(p)
    p.set_defaults(run=_run_simulate)


def _run_simulate(args) -> int:
    import numpy as np

    from ..exceptions import InputError
    from ..io.measurements import read_measurements
    from .common import robot_from_args
    from ..analysis.scenario import load_scenario, scenario_from_dict
    from ..analysis.reachable import PoseFilter
    from ..analysis.simulate import random_scenario, screened_poses, simulate_measurements, truth_text
    from .staging import write_text
    from .writers import write_measurements

    # --poses fixes the poses: these would be ignored
    for given, option in ((args.n, "--n"), (args.box, "--box"), (args.tracker_mm, "--tracker-mm"),
                          (args.below_mounting_plane or None, "--below-mounting-plane")):
        if given is not None and args.poses is not None:
            raise InputError(f"{option} with --poses {args.poses}: the file's rows are the poses; give one of them")
    args.n = 200 if args.n is None else args.n
    robot = robot_from_args(args)
    # the poses, their context and the CSV text: a few hundred bytes a measurement
    check_memory(args, f"--n {args.n}", args.n * (sample_bytes(robot) + 400.0))
    if args.poses is not None:
        check_csv_memory(args, args.poses, "--poses", sample_bytes(robot))
    rng = np.random.default_rng(args.seed)
    if args.scenario is not None and args.random is not None:
        raise InputError("--scenario and --random: give one of them")
    if args.outside is not None and args.random is None:
        raise InputError("--outside: only with --random (in a scenario file, list the effect under effects)")
    extra = {}
    if args.scenario is not None:
        scenario = load_scenario(args.scenario)
    else:
        spec = random_scenario(robot, rng, dominant=args.random or None, outside=args.outside)
        extra = {"dominant": spec["dominant"], "notes": spec["notes"]}
        scenario = scenario_from_dict(spec, source="--random")
    q = context = screened = None
    if args.poses is not None:
        poses = read_measurements(args.poses, robot, require_position=False)
        q, context = poses.q, poses.make_context(random_state=rng)
    box, tracker = reach_values(args)
    if q is None:  # drawn here, as simulate_measurements would, to say what was rejected
        pose_filter = PoseFilter.for_robot(robot, box=box, tracker=tracker,
                                           floor_z=None if args.below_mounting_plane else robot.mounting_plane_z)
        screened = screened_poses(robot, args.n, rng, pose_filter=pose_filter)
        q = screened.q
    noise = None if args.noise_mm is None else args.noise_mm * 1e-3
    mset, truth = simulate_measurements(robot, scenario, args.n, rng, noise, q=q, context=context,
                                        orientation=args.orientation)
    if args.poses is not None:  # a pose test's labels (pose_id, cycle, target_*_mm) go through
        mset.annotations = poses.annotations
    truth.update(extra)
    truth["seed"] = args.seed
    write_measurements(args.out, robot, mset, unit=args.unit)
    if args.truth:
        write_text(args.truth, truth_text(truth, args.truth))
    names = ", ".join(truth["effects"]) or "none"
    print(f"{robot.name}: {len(mset)} simulated measurements -> {args.out} "
          f"(hidden effects: {names}; noise {truth['noise_m'] * 1e3:.4g} mm)")
    if screened is not None:
        print(f"poses: random, {pose_filter.checks}"
              + (f" ({screened.tried} drawn: {screened.rejections()})" if screened.tried > len(q) else ""))
    if args.truth:
        status(args, f"hidden truth written to {args.truth}")
    return EXIT_OK
