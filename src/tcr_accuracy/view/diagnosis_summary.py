"""The printed summary of a diagnosis: what ``tcr-accuracy diagnose`` prints and
:func:`diagnosis_summary` returns (mm and deg, labelled).

Text only: it reads a :class:`~tcr_accuracy.diagnosis.result.Diagnosis` and imports nothing
heavy at load time (the command line's parser imports this module).
"""

from __future__ import annotations


def diagnosis_summary(diagnosis, source: str | None = None) -> str:
    """The summary ``tcr-accuracy diagnose`` prints (mm and deg, labelled).

    Parameters
    ----------
    diagnosis : Diagnosis
        A diagnosis' result (``GapDiagnosis(...).fit(...).result_`` or ``diagnose(...)``).
    source : str, default=None
        What the first line names as the measurements; None: the diagnosis' own ``source``.

    Returns
    -------
    str
        Several lines, in the order gap, where, which effect, how far it shrinks.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets", "compliance"], folds=3)
    >>> print(tcr.diagnosis_summary(d))  # doctest: +ELLIPSIS
    Diagnosis of examples/measured.csv: 200 measurements of tool_changer, 3-fold cross-validation...
    """
    return format_summary(None, diagnosis, diagnosis.source if source is None else source)


def format_summary(robot, d, source: str) -> str:
    """The printed summary of a diagnosis (mm and deg, labelled).

    Parameters
    ----------
    robot : RobotModel or None
        The robot diagnosed (its name and joint names); None: those the diagnosis recorded.
    d : Diagnosis
        The result.
    source : str
        What the first line names as the measurements (file names).

    Returns
    -------
    str
        The summary's lines.
    """
    import numpy as np

    robot_name = d.robot_name if robot is None else robot.name
    joint_names = list(d.joint_names if robot is None else robot.joint_names)
    mm = 1e3
    repeats = d.fold_assignments or 1  # None: a file of 0.1 does not say
    out = [f"Diagnosis of {source}: {d.n_measurements} measurements of {robot_name}, "
           f"{d.folds}-fold cross-validation" + (f" over {repeats} fold assignments" if repeats > 1 else "")]
    start = getattr(robot, "kinematics", None)
    if start:  # the nominal robot is the robot's own kinematics: every effect below is relative to them
        out.append(f"Nominal robot: the factory kinematics of {start['file']} ({start['format']}); every effect "
                   "below is relative to them")
    out.extend(answer_lines(d))
    out.append(f"\n1. Gap after fitting the tracker frame and TCP offset (frames): "
               f"mean {d.gap.mean * mm:.4f} mm, RMS {d.gap.rms * mm:.4f} mm, max {d.gap.max * mm:.4f} mm")
    if d.sessions:
        setup = d.session_setup
        owns = "each with its own tracker frame" if setup is None else SESSION_OWNS.get(setup["chosen"], setup["chosen"])
        out.append(f"   {len(d.sessions)} sessions, {owns} (the robot's parameters shared):")
        for s in d.sessions:
            t = s["temperature_c"]
            out.append(f"     {s['session']:20s} {s['n_measurements']:6d} rows, gap RMS {s['gap']['rms_mm']:.4f} mm, "
                       f"final held-out RMS {s['heldout']['rms_mm']:.4f} mm, temperature {t[0]:.1f} to {t[1]:.1f} degC")
    if d.sessions and d.session_setup is not None:
        out += session_setup_lines(d.session_setup)
    for drift in d.drift:
        if not drift.get("fitted", True):
            out.append(f"   tracker drift: session {drift['session']} not fitted ({drift['why']})")
            continue
        key = "drift_mm_per_h" if "drift_mm_per_h" in drift else "drift_mm_per_100_rows"
        unit = "mm/h" if key == "drift_mm_per_h" else "mm per 100 rows"
        speed = float(np.linalg.norm(drift[key]))
        out.append(f"   tracker drift seen by {', '.join(drift['references'])} (session {drift['session']}, in "
                   f"{drift['time_axis']}): {speed:.4f} +- {drift['drift_std_mm_per_unit']:.4f} {unit}, "
                   f"{drift['moved_over_session_mm']:.4f} mm over the session, z = {drift['z']:.1f}: "
                   + ("corrected" if drift["corrected"] else "not corrected (within the noise)"))
        for far in drift.get("outliers", [])[:5]:
            out.append(f"   base reference {far['reference']}, measurement {far['row'] + 1}: {far['off_mm']:.4g} mm off "
                       "the drift, left out of the drift and the noise (a bumped reflector, a broken beam?)")
    out.append("\n2. Where it lies (residual after frames)")
    axes = d.where_mm["per_axis"]
    out.append("   per axis RMS [mm]: " + ", ".join(f"{a} {axes[a]['rms_mm']:.4f}" for a in "xyz"))
    strongest = strongest_links(d.where_mm)
    if strongest:
        out.append("   strongest links: " + "; ".join(strongest))
    along = d.where_mm["along_joints"]
    out.append("   along single joints (share of the residual variance its k-NN along that joint predicts; "
               "short-lag semivariance, 1 = none): " + ", ".join(
                   f"{j} {a['knn_explained_share']:+.2f} ({min(a['short_lag_semivariance_xyz']):.2f})"
                   for j, a in along.items()))
    out.append("   varies most along: " + (", ".join(d.where_mm["varies_along"]) or
                                           "no single joint (the error depends on several together)"))
    pairs = [p for p in d.where_mm.get("along_joint_pairs", []) if p["knn_explained_share"] > 0.05][:3]
    if pairs:
        out.append("   joint pairs it varies along (k-NN share): " + ", ".join(
            f"{'+'.join(p['joints'])} {p['knn_explained_share']:+.2f}" for p in pairs))
    out.append("\n3. Which effect: each effect added to frames alone (held-out RMS [mm], gain, paired z)")
    for name, c in d.candidates.items():
        if c.get("tried"):
            out.append(f"   {name:18s} {c['heldout_rms_mm_with_frames']:9.4f} {c['gain_mm']:+9.4f} "
                       f"z = {c['z']:6.1f}  ({c['n_parameters']} identifiable parameters)")
        else:
            out.append(f"   {name:18s} not tried: {c['why']}")
    ident = d.identifiability
    removed = [(e, r) for e, info in ident["effects"].items() for r in info["removed"]]
    everything = ident.get("all_effects", {})
    out.append(f"   identifiability of the final model: {ident.get('rank', 0)} parameters kept, condition number "
               f"{ident.get('condition_number', float('nan')):.3g}; {len(removed)} removed, e.g.:")
    for e, r in removed[:6]:
        out.append(f"     {r['parameter']}: {r['reason']}")
    if everything:
        n_removed = sum(len(i["removed"]) for i in everything["effects"].values())
        out.append(f"   (whole vocabulary in one model: {everything.get('rank', 0)} identifiable, {n_removed} removed, "
                   f"condition number {everything.get('condition_number', float('nan')):.3g})")
    out.append("\n4. How far it shrinks (k-fold held-out, in the order the effects explain the data) [mm]")
    out.append(f"   {'step':18s} {'params':>6s} {'train RMS':>10s} {'mean':>9s} {'RMS':>9s} {'max':>9s}"
               f"   gain in RMS [95 % interval]")
    for i, s in enumerate(d.steps):
        label = s.effect if i == 0 else "+" + s.effect
        gain = "" if s.gain is None else f"   {s.gain[0] * mm:+.4f} [{s.gain[1] * mm:+.4f}, {s.gain[2] * mm:+.4f}]"
        out.append(f"   {label:18s} {s.n_parameters:6d} {s.train_rms * mm:10.4f} {s.heldout.mean * mm:9.4f} "
                   f"{s.heldout.rms * mm:9.4f} {s.heldout.max * mm:9.4f}{gain}")
    if d.leave_one_out:
        out.append("   leave one out of the chosen set (held-out RMS without it; the others refitted and free to "
                   "take its place / held to their own parameters, own share [95 % interval]):")
        for r in d.leave_one_out:
            low, high = r["own_share_interval_mm"]
            out.append(f"     without {r['dropped']:18s} {r['heldout_rms_mm']:9.4f} ({r['increase_mm']:+.4f})  /  "
                       f"{r['own_share_heldout_rms_mm']:9.4f} ({r['own_share_increase_mm']:+.4f} "
                       f"[{low:+.4f}, {high:+.4f}])")
    for e in d.eliminated:
        out.append(f"   dropped again in backward elimination: {e['effect']} (z = {e['z']:.1f})")
    for swap in d.swaps:
        out.append(f"   swapped after forward selection: {swap['in']} for {swap['out']} (as good held out, fewer "
                   f"parameters: {swap['n_parameters'][swap['in']]} against {swap['n_parameters'][swap['out']]})")
    if d.ambiguous:
        out.append("   the data cannot tell apart (each swapped for the chosen one and refitted; held-out RMS, "
                   "parameters):")
        for group in d.ambiguous:
            members = ", ".join(f"{m['effect']} {m['heldout_rms_mm']:.4f} mm / {m['n_parameters']}"
                                for m in group["members"])
            out.append(f"     {{{', '.join(group['effects'])}}}: {members}")
    out.append(f"   primary effect: {primary_effect_text(d)}")
    if d.families:
        out.append("   families (held-out RMS without all their members and their stand-ins, the others held to their "
                   "parameters; each below the largest by the difference of the two shares [95 % interval], "
                   "the selection's paired z):")
        for f in d.families:
            low, high = f["interval_mm"]
            beside = f" (stand-ins beside it: {', '.join(f['stand_ins'])})" if f.get("stand_ins") else ""
            below = f.get("below_largest")
            rank = "" if not below else (f"; {below['difference_mm']:.4f} mm [{below['interval_mm'][0]:+.4f}, "
                                         f"{below['interval_mm'][1]:+.4f}] below {below['larger']}, paired z = "
                                         f"{below['z']:.1f}" + ("" if below["ranked"] else ": not ranked apart"))
            out.append(f"     {f['family']:10s} {{{', '.join(f['effects'])}}}{beside}: +{f['share_mm']:.4f} mm "
                       f"[{low:+.4f}, {high:+.4f}]{rank}")
    selection = d.selection
    if selection.get("frequency"):
        chosen = [e for e in d.selected_effects if e != "frames"]
        others = [e for e, f in selection["frequency"].items() if e not in chosen and f > 0]
        out.append(f"   stability: chosen in {selection['n_replays']} bootstrap replays of the selection: "
                   + (", ".join(f"{e} {selection['frequency'].get(e, 0.0):.0%}" for e in chosen) or "nothing")
                   + (" (also chosen: " + ", ".join(f"{e} {selection['frequency'][e]:.0%}" for e in others) + ")"
                      if others else ""))
    out.extend(parameter_lines(d))
    final = d.steps[-1].heldout.rms
    noise = d.noise
    source = "tracker" if noise is None or noise.source == "given" else f"estimated from the {noise.source}"
    if noise is not None and not noise.independent:
        out.append(f"   final held-out RMS {final * mm:.4f} mm; noise floor at most {d.noise_floor * mm:.4f} mm "
                   f"({source} {d.tracker_noise * mm:.4f} mm per axis: an upper bound, so no verdict against it)")
    else:
        out.append(f"   final held-out RMS {final * mm:.4f} mm = {final / d.noise_floor:.2f} x the noise floor "
                   f"{d.noise_floor * mm:.4f} mm ({source} {d.tracker_noise * mm:.4f} mm per axis)")
    if noise is not None and noise.source != "given":
        out.append(f"   noise: {noise.detail}")
    st = d.structure
    along = ", ".join(joint_names[j] for j in st.get("along_joints", []))
    out.append(f"   structure remains: {structure_verdict_text(d)} (k-NN along {along}: share "
               f"{st['gain_over_null']:+.3f} "
               f"beyond chance, z = {st['z']:.1f}; ridge on joint features share {st['ridge_explained_share']:+.3f}, "
               f"z = {st['ridge_z']:.1f}; limits: share > {st['min_explained']}, p < {st['alpha']})")
    power = st.get("power", {})
    if power:
        seen, n = power.get("smallest_detectable_mm"), tested_poses_text(power)
        shapes = ", ".join(power.get("per_shape_mm", {}))
        if seen is not None:
            text = f"with {n} poses the test sees a leftover from {seen:.4g} mm RMS (the largest over {shapes})"
        else:
            unseen = ", ".join(k for k, v in power.get("per_shape_mm", {}).items() if v is None)
            text = f"with {n} poses the leftover of {unseen} goes unseen up to {power['largest_probed_mm']:.4g} mm"
        out.append(f"   power: {text}" + (f"; {st['reason']}" if st.get("verdict") == "cannot tell" else ""))
    sc = d.scatter
    if sc.get("tested", True):
        out.append(f"   random scatter beyond the tracker: {'YES' if sc['detected'] else 'no'} "
                   f"(estimated {sc['estimated_noise_per_axis_mm']:.4f} mm per axis, ratio {sc['ratio']:.2f})")
    else:
        out.append(f"   random scatter beyond the instrument: not tested ({sc['why']})")
    if d.orientation:
        o = d.orientation
        out.append(f"   orientation (held-out): mean {o['heldout_mean_deg']:.4f} deg, "
                   f"RMS {o['heldout_rms_deg']:.4f} deg, max {o['heldout_max_deg']:.4f} deg "
                   f"(weight {o['weight_m_per_rad'] * 1e3:.4g} mm/rad)")
    for frame, stats in d.heldout_by_frame.items():
        out.append(f"   measured frame {frame}: held-out mean {stats.mean * mm:.4f} mm, RMS {stats.rms * mm:.4f} mm, "
                   f"max {stats.max * mm:.4f} mm")
    if st["remains"]:
        out.append("   -> something the vocabulary does not express is still in the data: the fit is not the "
                   "whole story")
    said = {f"{m['effect']}: {a}" for m in d.mechanisms for a in m.get("assumed", [])}  # in the answer already
    out += [f"   note: {note}" for note in d.notes if note not in said]
    return "\n".join(out)


def parameter_lines(d, per_effect: int = 4) -> list[str]:
    """The fitted parameters, the largest of each effect (relative to its standard error),
    with unit, standard error, 95 % interval and physical range."""
    import numpy as np

    if not d.parameter_table:
        return []
    out = ["   fitted parameters (value +- standard error, 95 % interval, physical range; SI units; all in the JSON "
           "and the report):"]
    for e, table in d.parameter_table.items():
        if e == "frames":
            continue
        units = d.parameter_units.get(e, {})
        names = sorted(table["values"], key=lambda n: -abs(table["values"][n]))[:per_effect]
        out.append(f"     {e} ({len(table['values'])} parameters; {d.physics.get(e, '')})")
        for n in names:
            v, s = table["values"][n], table["std"][n]
            low, high = table["interval"][n]
            lo, hi = table["range"][n]
            out.append(f"       {n} = {v:+.4g} +- {s:.2g} {units.get(n, '')} [{low:+.3g}, {high:+.3g}], "
                       f"range {lo:.3g} to {hi:.3g}")
        for joint, band in d.joint_function_bands.get(e, {}).items():
            values = table["values"]
            amplitude = {}
            for name, v in values.items():
                parts = name.split(".")
                if parts[1] == joint:
                    order = int(parts[-1][1:])
                    amplitude[order] = amplitude.get(order, 0.0) + v * v
            top = max(amplitude, key=amplitude.get) if amplitude else None
            out.append(f"       {joint}: {np.sqrt(np.mean(band['value_rad'] ** 2)) * 1e6:.1f} urad RMS over "
                       f"{np.degrees(band['angle_rad'][0]):.0f} to {np.degrees(band['angle_rad'][-1]):.0f} deg "
                       f"(band +-{1.96 * np.mean(band['std_rad']) * 1e6:.1f} urad)"
                       + (f", strongest {top} cycles per revolution" if top else ""))
        if table["pinned"]:
            out.append("       held on a physical bound: " + ", ".join(
                f"{p['parameter']} ({p['bound']})" for p in table["pinned"][:6])
                + (f" and {len(table['pinned']) - 6} more" if len(table["pinned"]) > 6 else ""))
    tolerance = d.geometry_tolerance  # a view: a diagnosis read from its file has it too
    if d.geometry_checks and tolerance is not None:
        out.append(f"   the fitted geometry against what an {tolerance['robot_class']} allows (plausibility.py):")
        out += [f"     {'FLAG: ' if c['flagged'] else ''}{c['text']}" for c in d.geometry_checks]
    return out


#: What each session owns, in the words of the sessions' line, by the setup's name
SESSION_OWNS = {"one frame": "one tracker frame and one TCP offset for all",
                "tool offset per session": "one tracker frame, each with its own TCP offset",
                "frame per session": "each with its own tracker frame",
                "frame and tool offset per session": "each with its own tracker frame and TCP offset"}


def session_setup_lines(setup: dict) -> list[str]:
    """What each session owns: the setups compared (held-out RMS, parameters), the one chosen, and
    each later session's frame and TCP offset against the first's (mm, mrad, standard errors)."""
    tried = "; ".join(f"{c['setup']} {c['heldout_rms_mm']:.4f} mm ({c['n_parameters']} parameters)"
                      for c in setup["compared"])
    out = [f"   what each session owns: {setup['chosen']}, the simplest within one standard error of the best "
           f"(held-out RMS with {' + '.join(setup['judged_with'])}: {tried})"]
    if setup.get("forced"):
        out.append(f"     {setup['forced']}")
    if setup.get("reselected"):
        out.append("     (the setup chosen with frames alone differed: the selection ran again with this one"
                   + (f"; with its effects the comparison prefers {setup['preferred']}" if setup.get("preferred")
                      else "") + ")")
    for s in setup["sessions"]:
        parts = []
        if "translation_mm" in s:
            parts.append(f"tracker frame moved {s['translation_mm']:.3f} +- {s['translation_std_mm']:.3f} mm, turned "
                         f"{s['rotation_mrad']:.3f} +- {s['rotation_std_mrad']:.3f} mrad")
        if "tool_offset_mm" in s:
            offset = ", ".join(f"{v:+.3f}" for v in s["tool_offset_mm"])
            length = sum(v * v for v in s["tool_offset_mm"]) ** 0.5
            parts.append(f"TCP offset moved ({offset}) mm +- {max(s['tool_offset_std_mm']):.3f} mm, "
                         f"{length:.3f} mm in all")
        out.append(f"     {s['session']} against {s['against']}: " + "; ".join(parts))
    return out


def answer_lines(d) -> list[str]:
    """The answer first: the family and, where the data resolve it, the effect that causes the
    largest share of the gap, what mechanism each chosen effect's sign and size fit (and what its fit
    assumed), and the fitted geometry beyond what the robot's class allows."""
    out = ["Answer: " + family_answer(d.families, d.primary_family, d.primary_effect, d.primary_group)]
    for c in d.confounding:
        if c.get("drift_reproduces") and not c.get("confounded_effects"):  # judged on signatures: told apart
            out.append(f"  the order of measurement: {c['why']}")
            continue
        out.append(f"  mind the order of measurement: {c['why']}; tcr-accuracy plan-poses writes an order "
                   "that separates them")
    for m in d.mechanisms:
        if m["effect"] == "frames":
            continue
        mark = "" if m["physical"] else " [no known mechanism fits most of it]"
        out.append(f"  {m['effect']} ({m['family']}): {m['mechanism']}{mark}")
        for assumed in m.get("assumed", []):
            out.append(f"    assumed: {assumed}")
        if m["check"]:
            out.append(f"    check: {m['check']}")
    out += [f"  flag: {c['text']}" for c in d.geometry_checks if c["flagged"]]
    return out


def family_answer(families, primary_family, primary_effect, primary_group) -> str:
    """Which family of effects causes most of the gap and, where the data resolve it, which effect
    within it: one sentence from a diagnosis' ``families`` (dicts as in its JSON), primary family,
    primary effect and the group that stands in for it. The largest family is compared with the
    next (``below_largest``: the difference of the two shares and its 95 % interval, paired); where
    that interval holds zero the sentence says the rows do not rank them apart, and still which is
    the larger and by how much."""
    by_name = {f["family"]: f for f in families}
    runners = [f for f in families if f.get("below_largest")]
    if primary_family in by_name:
        f = by_name[primary_family]
        low, high = f["interval_mm"]
        head = (f"the gap is mostly {primary_family} ({f.get('what', '')}): without it the held-out RMS rises by "
                f"{f['share_mm']:.4g} mm [95 %: {low:.4g} to {high:.4g}]")
        if runners:
            head += f", more than {runners[0]['family']}'s by {_by_how_much(runners[0]['below_largest'])}"
        if primary_effect:
            head += f"; within it, {primary_effect}"
        elif len(primary_group) > 1:
            head += f"; the data do not tell apart {', '.join(primary_group)}"
        return head
    if primary_effect:
        return f"{primary_effect} causes the largest share of the gap"
    if families:
        tied = [f for f in runners if not f["below_largest"]["ranked"]] or families[1:3]
        return (f"the held-out rows do not rank the families apart: {_share_text(families[0])} is the larger, "
                + "; ".join(f"above {_share_text(f)} by {_by_how_much(f.get('below_largest'))}" for f in tied))
    return "nothing beyond the tracker frame and the TCP offset (frames) is resolved"


def _share_text(family: dict) -> str:
    low, high = family["interval_mm"]
    return f"{family['family']} +{family['share_mm']:.4g} mm [95 %: {low:.4g} to {high:.4g}]"


def _by_how_much(comparison: dict | None) -> str:
    """"0.107 mm [95 %: 0.017 to 0.19; paired z = 2.4, not above 3]": a difference of two shares with its
    interval and the selection's paired test (JSON form), and, where the rows do not rank them apart, why."""
    if not comparison:
        return "an amount not recorded"
    low, high = comparison["interval_mm"]
    text = f"{comparison['difference_mm']:.4g} mm [95 %: {low:.4g} to {high:.4g}"
    z = comparison.get("z")  # None in a JSON file for an infinite z (no spread at all)
    if z is not None:
        text += f"; paired z = {z:.1f}"
    if not comparison["ranked"]:
        text += (f", not above {comparison['z_threshold']:g}" if z is not None and z <= comparison["z_threshold"]
                 else "; the interval holds zero")
    return text + "]"


def primary_effect_text(d) -> str:
    """The primary effect, or the group that stands in for it and why; each with the difference of
    the largest own share and the next and its 95 % interval (paired)."""
    comparisons = {c["smaller"]: c for c in d.own_share_ranking}
    share = {r["dropped"]: r["own_share_increase_mm"] for r in d.leave_one_out}
    if d.primary_effect:
        text = f"{d.primary_effect} (the largest own share"
        runner = next((c for c in d.own_share_ranking if c["larger"] == d.primary_effect), None)
        if runner:
            text += (f", +{share[runner['larger']]:.4g} mm, above {runner['smaller']} +{share[runner['smaller']]:.4g} "
                     f"mm by {_by_how_much(runner)}")
        return text + ")"
    if len(d.primary_group) > 1:
        largest = d.primary_tied[0] if d.primary_tied else d.primary_group[0]
        tied = [e for e in d.primary_tied[1:] if e in d.primary_group]
        stand_ins = [e for e in d.primary_group if e not in tied and e != largest]
        why = []
        if stand_ins:
            why.append(f"{', '.join(stand_ins)} explain the data as well: measure poses that separate them, "
                       "see plan-poses")
        if tied:
            why.append("own shares not ranked apart by the held-out rows: " + "; ".join(
                f"{largest} +{share[largest]:.4g} mm above {e} +{share[e]:.4g} mm by "
                f"{_by_how_much(comparisons.get(e))}" for e in tied))
        return (f"one of {{{', '.join(d.primary_group)}}} (the largest own share is {largest}'s, but "
                + "; ".join(why) + ")")
    return "none beyond frames"


def structure_verdict_text(d) -> str:
    """YES, no, or "cannot tell with N poses": whether structure remains in the final residual."""
    st = d.structure
    verdict = st.get("verdict", "yes" if st["remains"] else "no")
    tested = tested_poses_text(st.get("power") or {"n_poses": d.n_measurements})
    return {"yes": "YES", "no": "no", "cannot tell": f"cannot tell with {tested} poses"}[verdict]


def tested_poses_text(power: dict) -> str:
    """"2000" or, when the structure test ran on a random subset, "20000 of the 100000"."""
    n, of = power["n_poses"], power.get("of_poses", power["n_poses"])
    return f"{n}" if of == n else f"{n} (a random subset) of the {of}"


def strongest_links(where: dict) -> list:
    """The four strongest links of the residual with joints, gravity torque, payload, temperature
    and approach direction, as text (from :attr:`Diagnosis.where_mm`)."""
    links = []
    for group, label in (("joints", "joint"), ("gravity_torque", "gravity torque")):
        for name, info in where.get(group, {}).items():
            if "correlation_xyz" not in info:
                continue
            corr = info["correlation_xyz"]
            c = int(max(range(3), key=lambda k: abs(corr[k])))
            links.append((abs(corr[c]), f"{label} {name} vs {'xyz'[c]}: r = {corr[c]:+.2f}, "
                                        f"binned spread {info['spread_mm']:.3f} mm"))
    for key in ("payload_kg", "temperature_c"):
        if key in where:
            corr = where[key]["correlation_xyz"]
            c = int(max(range(3), key=lambda k: abs(corr[k])))
            links.append((abs(corr[c]), f"{key} vs {'xyz'[c]}: r = {corr[c]:+.2f}"))
    for name, info in where.get("approach_direction", {}).items():
        links.append((0.0, f"approach direction {name}: +/- differ by {info['difference_norm_mm']:.4f} mm"))
    links.sort(key=lambda t: -t[0])
    return [text for _, text in links[:4]]
