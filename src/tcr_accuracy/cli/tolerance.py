"""CLI: ``tcr-accuracy tolerance``, the largest spreads that still meet a reliability target.

Tolerance allocation (:func:`tcr_accuracy.analysis.tolerance.allocate_tolerance`) at one pose,
for all groups of error sources at once or (``--per-group``) each alone. Heavy imports
live inside the run function so that ``--help`` stays instant.
"""

from __future__ import annotations

import math

from .common import (MAX_COUNT, MAX_MM, add_sampler_arguments, check_memory, error_sampler, format_joint_values,
                     integer, joint_values_si, number, sample_bytes)
from .output import RunOutput, add_output_arguments, progress_bar


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "tolerance", help="largest spreads that still meet a reliability target",
        description="Tolerance allocation: the largest factor on the spreads of the --preset (all "
                    "of them, or only those of --groups) such that P(|dP| < T) >= p at the pose, "
                    "from a fixed-seed Monte Carlo with common random numbers. Prints the "
                    "allowed spreads in mm and deg.",
    )
    add_sampler_arguments(p, pose=True)
    add_output_arguments(p, plots=False)
    p.add_argument("--target-tol", type=number(low=0, low_open=True, high=MAX_MM, unit="mm"), default=0.25,
                   metavar="MM",
                   help="position tolerance T on |dP| [mm] (default 0.25)")
    p.add_argument("--target-prob", type=number(low=0, high=1, low_open=True, high_open=True), default=0.95,
                   metavar="P",
                   help="required probability P(|dP| < T), in (0, 1) (default 0.95)")
    p.add_argument("--groups", default=None, metavar="G1,G2",
                   help="scale only these groups (table1/table2: link_length, drive, axis_deflection; "
                        "clearance: axial, radial, deflection); default all")
    p.add_argument("--per-group", action="store_true",
                   help="also the allowance of each group alone, the others at their spreads")
    p.add_argument("--samples", type=integer(low=10, high=MAX_COUNT), default=50_000,
                   help="Monte Carlo samples (default 50000)")
    p.set_defaults(run=_run_tolerance)


def _run_tolerance(args) -> int:
    import numpy as np

    from ..exceptions import AnalysisError, InputError
    from ..analysis.random_inputs import random_inputs
    from .common import robot_from_args
    from ..analysis.tolerance import allocate_tolerance

    if args.samples * (1.0 - args.target_prob) < 1.0:  # fewer than one expected miss: 1.0 is all it can say
        raise InputError(f"--target-prob {args.target_prob:.10g}: {args.samples} samples cannot tell it from 1 "
                         f"(not one miss expected); use about {10 / (1.0 - args.target_prob):.2g} --samples "
                         "(ten misses expected), or a lower --target-prob")
    out = RunOutput(args, "Tolerance allocation")
    robot = robot_from_args(args)
    q = joint_values_si(robot, args.q)
    check_memory(args, f"--samples {args.samples}", args.samples * sample_bytes(robot))
    sampler, label = error_sampler(robot, args)
    inputs = random_inputs(sampler)
    known = sorted({g for g, ok in zip(inputs.groups, inputs.scalable) if ok})
    groups = None
    if args.groups:
        groups = [g.strip() for g in args.groups.split(",") if g.strip()]
        unknown = [g for g in groups if g not in known]
        if unknown or not groups:
            raise InputError(f"--groups {args.groups}: unknown group {', '.join(unknown) or '(none given)'} "
                             f"(groups of {label}: {', '.join(known)})")
    tol = args.target_tol * 1e-3
    update, close = progress_bar(None, "tolerance (Monte Carlo runs)", args.quiet)
    try:
        main = allocate_tolerance(sampler, q, tol, args.target_prob, groups=groups, n_samples=args.samples,
                                  rng=np.random.default_rng(args.seed), progress=update)
        per_group = {}
        if args.per_group:
            for g in known:
                try:
                    per_group[g] = allocate_tolerance(sampler, q, tol, args.target_prob, groups=[g],
                                                      n_samples=args.samples, rng=np.random.default_rng(args.seed),
                                                      progress=update)
                except AnalysisError as exc:
                    per_group[g] = str(exc)
    finally:
        close()

    payload = {
        "robot": robot.name, "preset": label, "joint_names": robot.joint_names,
        "joint_values_si": q.tolist(), "tolerance_m": tol, "target_probability": args.target_prob,
        "n_samples": args.samples, "seed": args.seed, **_allocation_json(main),
    }
    if args.per_group:
        payload["per_group"] = {g: (_allocation_json(a) if not isinstance(a, str) else {"error": a})
                                for g, a in per_group.items()}
    head = _tolerance_head(robot, q, label, args, main)
    out.add_text("\n\n".join(head), heading="Setup and result")
    out.add_table("Allowed spreads (standard deviations)", ["source", "group", "std now", "std allowed", "unit"],
                  _spread_rows(main))
    if args.per_group:
        out.add_table("Each group alone (the others at their spreads)", ["group", "largest factor"],
                      [(g, a if isinstance(a, str) else a.factor) for g, a in per_group.items()],
                      float_format="{:.6g}")
    return out.finish(payload, lambda: _print_tolerance(head, main, per_group if args.per_group else None))


def _tolerance_head(robot, q, label, args, main) -> list[str]:
    what = ", ".join(main.scaled_groups) if main.scaled_groups else "all"
    return [f"{robot.name}, preset {label}, at {format_joint_values(robot, q)}",
            f"Target P(|dP| < {args.target_tol:g} mm) >= {args.target_prob:g}; {args.samples} samples, "
            f"seed {args.seed}",
            f"  with the preset's spreads:  P = {main.nominal_probability:.4f}",
            f"  largest factor on the spreads ({what}): {main.factor:.6g}  (P = {main.achieved_probability:.4f})"]


def _spread_rows(allocation) -> list[tuple]:
    """(source, group, std now, std allowed, unit) in mm or deg."""
    rows = []
    for s in allocation.spreads:
        scale, unit = (1e3, "mm") if s.unit == "m" else (180.0 / math.pi, "deg")
        rows.append((s.name, s.group, s.nominal_std * scale, s.allowed_std * scale, unit))
    return rows


def _print_tolerance(head, main, per_group) -> None:
    print("\n".join(head))
    w = max(26, *(len(s.name) for s in main.spreads))
    print(f"  {'source':{w}s} {'group':16s} {'std now':>14s} {'std allowed':>14s}")
    for name, group, now, allowed, unit in _spread_rows(main):
        print(f"  {name:{w}s} {group:16s} {now:10.5g} {unit:3s} {allowed:10.5g} {unit:3s}")
    if per_group is not None:
        print("  each group alone (the others at their spreads):")
        for g, a in per_group.items():
            if isinstance(a, str):
                print(f"    {g:16s} impossible: {a}")
            else:
                print(f"    {g:16s} factor {a.factor:.6g}")


def _allocation_json(a) -> dict:
    spreads = []
    for s in a.spreads:
        u = s.unit
        spreads.append({"name": s.name, "group": s.group, f"nominal_std_{u}": s.nominal_std,
                        f"allowed_std_{u}": s.allowed_std})
    return {"factor": a.factor, "scaled_groups": list(a.scaled_groups) if a.scaled_groups else None,
            "nominal_probability": a.nominal_probability, "achieved_probability": a.achieved_probability,
            "spreads": spreads}
