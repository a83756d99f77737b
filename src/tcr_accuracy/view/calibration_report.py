"""The calibration report's first page: what a customer reads and signs, from the JSON results.

Built from the JSON documents the commands write (``diagnose --json``, ``iso9283 evaluate
--json``, ``compare --json``), so that ``diagnose --out`` and ``tcr-accuracy report
DIAGNOSIS.json ISO.json ...`` show the same page with the same numbers::

    campaign = Campaign(robot=RobotFacts.from_documents(docs), documents=[("d.json", doc), ...],
                        files=[("diagnosis JSON", "../d.json")])
    html_fragment, markdown = first_page(campaign, created="2026-11-24 10:00:00 UTC")
    report.set_first_page(html_fragment, markdown)
    add_technical_tables(report, campaign)   # for documents whose command is not run here

The page holds: the robot (name, URDF source, joints), the instrument (tracker noise and where
it came from), the date, the data (poses, sessions, files), the TCP error before and after
(k-fold held-out mean / RMS / max; ISO 9283 AP and RP when a pose test is given), the effects
found with each parameter's value, unit, 95 % interval and physical range, what remains, what
to do next (the ``plan-poses`` command line to run and what to check on the robot), the files,
and lines to sign. Values in display units (mm, deg, deg/kNm, ...: :data:`tcr_accuracy.units.DISPLAY_UNITS`).
"""

from __future__ import annotations

import html
import shlex
from dataclasses import dataclass, field

from ..exceptions import InputError
from ..units import display_value

#: The kinds of JSON result a report reads, and the keys that tell each apart.
KINDS = {
    "diagnosis": ("steps", "selected_effects", "parameters", "noise_floor_mm"),
    "iso9283": ("poses", "summary", "n_readings", "frame"),
    "comparison": ("changes", "tcp_effect", "z_threshold", "old", "new"),
}

#: At most this many parameters on the first page of a diagnosis alone (the largest relative to their standard error
#: of each effect); all of them are in the technical detail.
FIRST_PAGE_PARAMETERS = 18

#: Who signs the report (one column each, with name, signature and date).
SIGNATURES = ("Prepared by", "Checked by")

#: The command a campaign's next poses come from, and how many it suggests.
NEXT_POSES = 30


def kind_of(doc, source: str) -> str:
    """Which result ``doc`` is ("diagnosis", "iso9283", "comparison"); InputError naming ``source`` if none."""
    if isinstance(doc, dict):
        for kind, keys in KINDS.items():
            if all(k in doc for k in keys):
                return kind
    raise InputError(f"{source}: not a result of tcr-accuracy diagnose, iso9283 evaluate or compare (--json); "
                     "a calibration report is made of those")


def kind_or_none(doc) -> str | None:
    """Which result ``doc`` is, or None when it is none of :data:`KINDS`."""
    try:
        return kind_of(doc, "")
    except InputError:
        return None


@dataclass(frozen=True)
class RobotFacts:
    """What the first page says of the robot."""

    name: str
    source: str  # "tool_changer", an example-robot-data name or the URDF's path
    tool_frame: str
    joints: tuple = ()  # ((name, "revolute" | "prismatic"), ...); empty when not recorded

    @staticmethod
    def of_robot(robot, source: str) -> "RobotFacts":
        """From a loaded :class:`~tcr_accuracy.model.robot.RobotModel` and how it was loaded."""
        return RobotFacts(robot.name, str(source), robot.tool_frame, tuple(zip(robot.joint_names, robot.joint_kinds)))

    @staticmethod
    def from_documents(documents) -> "RobotFacts":
        """From JSON results (a diagnosis records its joints' units; the others only names)."""
        name = source = tool = ""
        joints: tuple = ()
        for _, doc in documents:
            name = name or str(doc.get("robot") or "")
            source = source or str(doc.get("robot_source") or "")
            tool = tool or str(doc.get("tool_frame") or doc.get("tool") or "")
            where = doc.get("where", {}).get("joints", {}) if isinstance(doc.get("where"), dict) else {}
            if not joints and where:
                joints = tuple((j, "prismatic" if info.get("unit") == "m" else "revolute") for j, info in where.items())
        return RobotFacts(name or "not recorded", source or name or "not recorded", tool or "not recorded", joints)


@dataclass
class Campaign:
    """The results one report gathers, with their file names, and the files written with them.

    documents : list of (source, dict)
        JSON results, each of a kind of :data:`KINDS`, labelled by their file (or command).
    files : list of (label, href)
        Links to the files written with the report (relative to the report folder).
    """

    robot: RobotFacts
    documents: list
    files: list = field(default_factory=list)

    def of_kind(self, kind: str) -> list:
        return [(s, d) for s, d in self.documents if kind_of(d, s) == kind]


# ---------------------------------------------------------------------------------------
# The page as blocks, rendered to HTML and Markdown
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Code:
    """A command line shown as code inside a text."""

    text: str


def _text(parts) -> tuple:
    return tuple(parts) if isinstance(parts, (list, tuple)) else (parts,)


def first_page(campaign: Campaign, created: str) -> tuple[str, str]:
    """The first page as (HTML fragment, Markdown). ``created``: the report's date line."""
    blocks = _blocks(campaign, created)
    return _html(blocks), _markdown(blocks)


def _blocks(c: Campaign, created: str) -> list:
    diagnoses, isos, comparisons = (c.of_kind(k) for k in ("diagnosis", "iso9283", "comparison"))
    d = diagnoses[-1][1] if diagnoses else None
    out: list = [("h1", f"Calibration report: {c.robot.name}")]
    out.append(("facts", _facts(c, created, d, diagnoses, isos, comparisons)))
    out.append(("h2", "Accuracy before and after"))
    out.append(_accuracy_table(d, isos))
    if d is not None:
        out.append(("h2", "Effects found"))
        # the page holds about this many table rows besides the rest: fewer parameters with a pose
        # test's or a comparison's rows (the others are in the technical detail)
        room = FIRST_PAGE_PARAMETERS - 3 * len(isos) - sum(6 + 2 * len(cmp.get("significant") or []) for _, cmp in
                                                            comparisons)
        out += _effects(d, max(room, 6))
        out.append(("h2", "What remains"))
        out.append(("list", _remains(d)))
    for source, cmp in comparisons:
        out.append(("h2", f"Changes since the earlier campaign ({cmp['old']})"))
        out += _changes(cmp)
    out.append(("h2", "What to do next"))
    out.append(("list", _next_steps(c, d, isos, comparisons)))
    if c.files:
        out.append(("links", list(c.files)))
    out.append(("signatures",))
    return out


def _facts(c, created, d, diagnoses, isos, comparisons) -> list:
    r = c.robot
    joints = (", ".join(f"{j} ({k})" for j, k in r.joints) if r.joints else "not recorded in the results")
    rows = [("Robot", f"{r.name}; URDF: {_urdf_source(r.source)}; TCP frame {r.tool_frame}"),
            ("Joints", f"{len(r.joints)}: {joints}" if r.joints else joints)]
    if d is not None:
        noise = d.get("noise") or {}
        axis, floor = d.get("tracker_noise_mm"), d.get("noise_floor_mm")
        how = {"given": "given for the instrument (--noise-mm)",
               "repeated poses": "estimated from repeated readings of the same poses",
               "residual": "estimated from the final residual (an upper bound: the instrument may be better)",
               "residual nugget": "estimated from the part of the residual that does not vary with the joints"}
        rows.append(("Instrument", f"tracker noise {_mm(axis)} mm per axis, noise floor {_mm(floor)} mm "
                                   f"(sqrt(3) x per axis); {how.get(noise.get('source'), noise.get('source', ''))}"))
    else:
        rows.append(("Instrument", "noise not estimated (no diagnosis in this report)"))
    rows.append(("Date", f"{created[:10]} (report written {created[11:]} by tcr-accuracy)"))
    data = []
    for source, doc in diagnoses:
        sessions = doc.get("sessions") or []
        data.append(("" if len(diagnoses) == 1 else f"diagnosis {source}: ") + f"{doc['n_measurements']} measured poses in "
                    f"{max(len(sessions), 1)} session{'s' if len(sessions) > 1 else ''} "
                    f"({doc.get('measurements', '')}), {doc.get('folds')}-fold cross-validation")
    for source, doc in isos:
        data.append(f"ISO 9283 pose test {doc.get('measurements', source)}: {doc['n_readings']} readings at "
                    f"{len(doc['poses'])} poses")
    for source, doc in comparisons:
        data.append(f"comparison: {doc['old']} (old) against {doc['new']} (new), TCP effect over "
                    f"{doc['tcp_effect']['n_poses']} poses")
    rows.append(("Data", data))
    return rows


def _urdf_source(source: str) -> str:
    if source == "tool_changer":
        return "built-in shield-machine tool-changer (tcr-accuracy)"
    if "/" in source or source.endswith(".urdf"):
        return source
    return f"example-robot-data {source}"


def _mm(value) -> str:
    return "-" if value is None else f"{value:.4f}"


def _accuracy_table(d, isos) -> tuple:
    rows = []
    if d is not None:
        first, last = d["steps"][0], d["steps"][-1]
        for what, key in (("mean", "heldout_mean_mm"), ("RMS", "heldout_rms_mm"), ("max", "heldout_max_mm")):
            rows.append((f"TCP position error, held-out {what}", _mm(first[key]), _mm(last[key]), "mm"))
    for source, iso in isos:
        after = (iso.get("compensated") or {}).get("summary", {})
        name = iso.get("measurements", source)
        rows.append((f"ISO 9283 pose accuracy AP_P, largest of {len(iso['poses'])} poses ({name})",
                     _mm(iso["summary"]["ap_max_mm"]), _mm(after.get("ap_max_mm")) + _predicted(after), "mm"))
        rows.append((f"ISO 9283 repeatability RP_l, largest ({name})", _mm(iso["summary"]["rp_max_mm"]),
                     _mm(after.get("rp_max_mm")) + _predicted(after), "mm"))
    note = []
    if d is not None:
        note.append("Held-out: each figure from poses not used in the fit (k-fold cross-validation). Before: the "
                    "nominal model, only the tracker frame and TCP offset fitted; after: with the effects below.")
    if isos:
        note.append("ISO 9283: before as measured; after predicted with the diagnosis given to iso9283 evaluate "
                    "--model ('-': none given).")
    if not rows:
        rows.append(("no accuracy figures in these results", "-", "-", ""))
    return ("table", ("figure", "before", "after", "unit"), rows, " ".join(note), "accuracy")


def _predicted(after) -> str:
    return " (predicted)" if after else ""


def _effects(d, limit: int) -> list:
    selected = [e for e in d["selected_effects"] if e != "frames"]
    if not selected:
        return [("p", "No effect beyond the tracker frame and the TCP offset explains the data significantly.")]
    gains = {s["effect"]: s for s in d["steps"][1:]}
    frequency = d.get("selection_frequency") or {}
    replays = (d.get("selection") or {}).get("n_replays", 0)
    quotas = _quotas({e: len(d["parameters"].get(e, {})) for e in selected}, limit)
    rows, left_out = [], 0
    for e in selected:
        physical = (d.get("physical") or {}).get(e, {})
        step = gains.get(e, {})
        gain = step.get("gain_heldout_rms_mm")
        interval = step.get("gain_interval_mm") or [None, None]
        head = [f"{e}: held-out RMS {_mm(gain)} mm lower"
                + (f" (95 %: {_mm(interval[0])} to {_mm(interval[1])})" if interval[0] is not None else "")]
        if replays:
            head.append(f"chosen in {frequency.get(e, 0.0):.0%} of {replays} replays")
        head.append("plausible" if physical.get("plausible", True) else "OUTSIDE its physical range")
        rows.append(("group", ", ".join(head)))
        names = list(d["parameters"].get(e, {}))
        shown = set(sorted(names, key=lambda n: -_significance(d, e, n))[:quotas[e]])  # the best determined
        rows += [_parameter_row(d, e, n, physical) for n in names if n in shown]
        left_out += len(names) - len(shown)
    note = ("+- std: standard error from the measurement noise (not model error); 95 % interval: value +- 1.96 std "
            "within the physical range, where the fit is held. The tracker frame and the reflector's offset on the "
            "tool (frames) belong to the setup: see the technical detail")
    note += (f", with the {left_out} parameters left out here." if left_out else ".")
    return [("table", ("parameter", "value", "+- std", "95 % interval", "physical range", "unit"), rows, note,
             "effects")]


def _quotas(sizes: dict, limit: int) -> dict:
    """How many parameters of each effect the first page shows, ``limit`` in all: the smaller effects
    whole, the rest shared out (at least 2 each)."""
    quotas, left = {}, limit
    pending = sorted(sizes, key=sizes.get)
    while pending:
        e = pending.pop(0)
        quotas[e] = min(sizes[e], max(left // (len(pending) + 1), 2))
        left -= quotas[e]
    return quotas


def _significance(d, effect: str, name: str) -> float:
    value = d["parameters"][effect][name]
    std = (d.get("parameter_std") or {}).get(effect, {}).get(name)
    return abs(value) / std if std else abs(value)


def _parameter_row(d, effect: str, name: str, physical: dict) -> tuple:
    unit = (d.get("parameter_units") or {}).get(effect, {}).get(name, "")
    value, shown = display_value(d["parameters"][effect][name], unit)
    std = (d.get("parameter_std") or {}).get(effect, {}).get(name)
    low, high = (d.get("parameter_interval_95") or {}).get(effect, {}).get(name, [None, None])
    lo, hi = (physical.get("range") or {}).get(name, [None, None])
    pinned = any(p.get("parameter") == name for p in physical.get("pinned", []))

    def v(x, fmt="{:+.4g}"):
        return "-" if x is None else fmt.format(display_value(x, unit)[0])

    physical_range = ("unbounded" if lo is None and hi is None else f"{v(lo, '{:.3g}')} to {v(hi, '{:.3g}')}")
    return (name, f"{value:+.4g}", v(std, "{:.2g}"), f"{v(low)} to {v(high)}",
            physical_range + (" (held on a bound)" if pinned else ""), shown)


def _remains(d) -> list:
    last = d["steps"][-1]
    noise = d.get("noise") or {}
    floor = d.get("noise_floor_mm")
    ratio = last["heldout_rms_mm"] / floor if floor else float("nan")
    items = [f"Held-out RMS after calibration {_mm(last['heldout_rms_mm'])} mm = {ratio:.2f} x the noise floor "
             f"{_mm(floor)} mm" + ("" if noise.get("independent", True) else
                                    " (the floor is estimated from this residual: an upper bound)") + "."]
    verdict = d.get("structure_verdict") or ("yes" if d.get("structure_remains") else "no")
    reason = (d.get("structure") or {}).get("reason", "")
    said = {"yes": "YES: the residual still varies with the joints, so an effect the model lacks is in the data",
            "no": "no: what is left looks like measurement scatter",
            "cannot tell": f"cannot tell with {d['n_measurements']} poses"}.get(verdict, verdict)
    items.append(f"Structure left in the residual: {said}" + (f" ({reason})" if reason else "") + ".")
    scatter = d.get("extra_scatter") or {}
    if scatter.get("tested"):
        items.append("Random scatter beyond the instrument: " + ("YES (play, clearance)" if scatter.get("detected")
                                                                  else "none found") + ".")
    for finding in d.get("outside_physics") or []:
        items.append(f"{finding.get('description', '')}")
    return items


def _next_steps(c: Campaign, d, isos, comparisons) -> list:
    items = []
    if d is not None:
        command = plan_poses_command(c.robot, d)
        groups = [g["effects"] for g in d.get("ambiguous") or []]
        verdict = d.get("structure_verdict") or ("yes" if d.get("structure_remains") else "no")
        if groups:
            why = ("to tell apart what these measurements cannot: "
                   + "; ".join("{" + ", ".join(g) + "}" for g in groups))
        elif verdict in ("yes", "cannot tell"):
            why = "to find or rule out what the model may still lack (more poses where the model is least known)"
        else:
            why = "to confirm the calibration on poses where it informs the model most, or after a change to the robot"
        items.append(("Measure the next poses, " + why + ": ", _Code(command),
                      " (then diagnose all the measurements together)."))
        for g in d.get("ambiguous") or []:
            items.append(f"Check on the robot which of {', '.join(g['effects'])} it is (they explain the data "
                         "equally well).")
        for e, info in (d.get("physical") or {}).items():
            for p in info.get("pinned", [])[:3]:
                items.append(f"Check {p.get('parameter')} on the robot: the fit holds it on its physical bound "
                             f"({p.get('bound')}).")
            if not info.get("plausible", True):
                items.append(f"Check {e} on the robot: its fitted values lie outside physics ({info.get('reason', '')}).")
        for finding in d.get("outside_physics") or []:
            items.append(f"Check {finding.get('effect')} on the robot: the data fit it only outside physics.")
        items += [f"Note: {n}" for n in d.get("notes") or []]
        items += _calibration_forms(d, c)
    else:
        items.append(("To calibrate, measure the robot at 100 or more poses spread over the joint ranges and run ",
                      _Code(f"tcr-accuracy diagnose MEASUREMENTS.csv{_robot_options(c.robot)} --json diagnosis.json"),
                      "; then gather the results: ", _Code("tcr-accuracy report diagnosis.json ... --out report")))
    for _, iso in isos:
        items += [f"ISO 9283 note: {n}" for n in iso.get("notes") or []]
    for _, cmp in comparisons:
        for name in cmp.get("significant") or []:
            items.append(f"Check on the robot what changed {name} between the campaigns (beyond both fits' "
                         "uncertainty).")
    return items


def _calibration_forms(d, c: Campaign) -> list:
    """How to carry the calibration to the robot: the forms and what they reach (the calibration
    URDF's figures where the diagnosis wrote it, the full model's k-fold held-out figure)."""
    from .as_built_summary import urdf_phrase

    sources = [s for s, _ in c.of_kind("diagnosis")]
    path = sources[-1] if sources and str(sources[-1]).endswith(".json") else "DIAGNOSIS.json"
    as_built = d.get("as_built") if isinstance(d.get("as_built"), dict) else {}
    urdf = urdf_phrase(as_built.get("accuracy") or [])
    steps = d.get("steps") or []
    final = steps[-1].get("heldout_mean_mm") if steps and isinstance(steps[-1], dict) else None
    full = f" ({final:.4f} mm mean k-fold held-out)" if isinstance(final, float) else ""
    return [(f"Load the calibration into the controller{': ' + urdf if urdf else ''}. ",
             _Code(f"tcr-accuracy export {shlex.quote(str(path))} --to calibration"),
             " writes it as a URDF (the TCP frame unchanged, the measured point a frame of its own), DH tables, the UR "
             f"driver's calibration file and a compensation filter that carries the full model{full}, each with "
             "what it reaches.")]


def _robot_options(robot: RobotFacts) -> str:
    if robot.source in ("tool_changer", "", "not recorded"):
        return ""
    return f" --robot {shlex.quote(robot.source)} --tool {shlex.quote(robot.tool_frame)}"


def plan_poses_command(robot: RobotFacts, d) -> str:
    """The ``plan-poses`` command line for the measurements of a diagnosis (its first session's file)."""
    files = [f.strip() for f in str(d.get("measurements", "MEASUREMENTS.csv")).split(",") if f.strip()]
    return (f"tcr-accuracy plan-poses {shlex.quote(files[0] if files else 'MEASUREMENTS.csv')}"
            f"{_robot_options(robot)} -k {NEXT_POSES} --out next_poses.csv")


def _changes(cmp) -> list:
    rows = []
    for ch in cmp["changes"]:
        if not ch.get("significant"):
            continue
        old, unit = display_value(ch["old"], ch["unit"])
        new = display_value(ch["new"], ch["unit"])[0]
        change = display_value(ch["change"], ch["unit"])[0]
        se = ch.get("std_error")
        rows.append((ch["parameter"], f"{old:+.4g}", f"{new:+.4g}",
                     f"{change:+.4g}" + ("" if se is None else f" +- {display_value(se, ch['unit'])[0]:.2g}"),
                     "-" if ch.get("z") is None else f"{ch['z']:.1f}", unit))
    tcp = cmp["tcp_effect"]
    text = (f"{len(rows)} of {len(cmp['changes'])} robot parameters changed beyond {cmp['z_threshold']:g} standard "
            f"errors; on the TCP over {tcp['n_poses']} poses the significant changes move it by mean "
            f"{_mm(tcp['significant_changes']['mean_mm'])} mm, max {_mm(tcp['significant_changes']['max_mm'])} mm "
            f"(all changes: max {_mm(tcp['all_changes']['max_mm'])} mm).")
    if not rows:
        return [("p", text)]
    return [("p", text), ("table", ("parameter", "old", "new", "change +- std error", "z", "unit"), rows, "",
                          "changes")]


# ---------------------------------------------------------------------------------------
def _inline_html(parts) -> str:
    return "".join(f'<code class="command">{html.escape(p.text)}</code>' if isinstance(p, _Code) else
                   html.escape(str(p)) for p in _text(parts))


def _inline_md(parts) -> str:
    from . import markdown_text as md

    return "".join(md.code(p.text) if isinstance(p, _Code) else md.line(p) for p in _text(parts))


def _html(blocks) -> str:
    esc = html.escape
    out = []
    for block in blocks:
        kind = block[0]
        if kind == "h1":
            out.append(f"<h1>{esc(block[1])}</h1>")
        elif kind == "h2":
            out.append(f"<h2>{esc(block[1])}</h2>")
        elif kind == "p":
            cls = f' class="{block[2]}"' if len(block) > 2 else ""
            out.append(f"<p{cls}>{_inline_html(block[1])}</p>")
        elif kind == "facts":
            rows = "".join(f"<tr><th>{esc(k)}</th><td>"
                           + ("<br>".join(esc(x) for x in v) if isinstance(v, list) else esc(v)) + "</td></tr>"
                           for k, v in block[1])
            out.append(f'<table class="facts"><tbody>{rows}</tbody></table>')
        elif kind == "table":
            _, columns, rows, note, cls = block
            head = "".join(f"<th>{esc(c)}</th>" for c in columns)
            body = []
            for row in rows:
                if row[0] == "group":
                    body.append(f'<tr class="group"><td class="text" colspan="{len(columns)}"><b>'
                                f"{esc(row[1])}</b></td></tr>")
                else:
                    body.append("<tr>" + "".join(f"<td>{esc(str(x))}</td>" for x in row) + "</tr>")
            out.append(f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>')
            if note:
                out.append(f'<p class="note">{esc(note)}</p>')
        elif kind == "list":
            out.append("<ul>" + "".join(f"<li>{_inline_html(item)}</li>" for item in block[1]) + "</ul>")
        elif kind == "links":
            out.append('<p class="files">Files: ' + "; ".join(f'<a href="{esc(href)}">{esc(label)}</a>'
                                                              for label, href in block[1]) + ".</p>")
        elif kind == "signatures":
            out.append('<table class="signatures"><thead><tr>' + "".join(
                f"<th>{who}</th>" for who in SIGNATURES) + "</tr></thead><tbody><tr>" + "".join(
                "<td>name, signature, date</td>" for _ in SIGNATURES) + "</tr></tbody></table>")
    return "\n".join(out)


def _markdown(blocks) -> str:
    """The blocks as Markdown, every string made safe there (:mod:`tcr_accuracy.view.markdown_text`)."""
    from . import markdown_text as md

    out = []
    for block in blocks:
        kind = block[0]
        if kind == "h1":
            out += [f"# {md.line(block[1])}", ""]
        elif kind == "h2":
            out += [f"## {md.line(block[1])}", ""]
        elif kind == "p":
            out += [_inline_md(block[1]), ""]
        elif kind == "facts":
            for k, v in block[1]:
                out += [f"- **{md.line(k)}**: " + md.line("; ".join(v) if isinstance(v, list) else v)]
            out.append("")
        elif kind == "table":
            _, columns, rows, note, _ = block
            out += ["| " + " | ".join(map(md.cell, columns)) + " |", "|" + "|".join("---" for _ in columns) + "|"]
            for row in rows:
                cells = [f"**{md.cell(row[1])}**"] + [""] * (len(columns) - 1) if row[0] == "group" else \
                    [md.cell(c) for c in row]
                out.append("| " + " | ".join(cells) + " |")
            out += ["", md.text(note), ""] if note else [""]
        elif kind == "list":
            out += [f"- {_inline_md(item)}" for item in block[1]] + [""]
        elif kind == "links":
            out += ["Files: " + "; ".join(f"[{md.label(label)}]({md.href(href)})" for label, href in block[1]) + ".",
                    ""]
        elif kind == "signatures":
            out += ["| " + " | ".join(SIGNATURES) + " |", "|" + "|".join("---" for _ in SIGNATURES) + "|",
                    "| " + " | ".join("name, signature, date" for _ in SIGNATURES) + " |", ""]
    return "\n".join(out)


# ---------------------------------------------------------------------------------------
# Technical detail from the JSON (for results whose command does not run with the report)
# ---------------------------------------------------------------------------------------
def add_technical_tables(report, campaign: Campaign, kinds=("diagnosis", "iso9283", "comparison")) -> None:
    """Add the tables of each result of ``kinds`` to ``report`` (anything with ``add_table``/``add_text``)."""
    for source, doc in campaign.documents:
        kind = kind_of(doc, source)
        if kind not in kinds:
            continue
        if kind == "diagnosis":
            _diagnosis_tables(report, source, doc)
        elif kind == "iso9283":
            add_iso_tables(report, source, doc)
        else:
            _comparison_tables(report, source, doc)


def _diagnosis_tables(report, source: str, d) -> None:
    report.add_table(f"How far the gap shrinks ({source}; k-fold held-out, in the order the effects explain it)",
                     ["step", "parameters", "train RMS", "held-out mean", "held-out RMS", "held-out max", "gain",
                      "gain 95 % interval"],
                     [(s["effect"] if i == 0 else "+" + s["effect"], s["n_parameters"], s["train_rms_mm"],
                       s["heldout_mean_mm"], s["heldout_rms_mm"], s["heldout_max_mm"],
                       s.get("gain_heldout_rms_mm", ""),
                       "" if not s.get("gain_interval_mm") else
                       f"{s['gain_interval_mm'][0]:+.4f} to {s['gain_interval_mm'][1]:+.4f}")
                      for i, s in enumerate(d["steps"])], units=["", "", "mm", "mm", "mm", "mm", "mm", "mm"])
    rows = []
    for e in d["parameters"]:
        physical = (d.get("physical") or {}).get(e, {})
        rows += [_parameter_row(d, e, n, physical) for n in d["parameters"][e]]
    report.add_table(f"Fitted parameters ({source})", ["parameter", "value", "standard error", "95 % interval",
                                                       "physical range", "unit"], rows,
                     note="display units; " + "; ".join(f"{e}: {info.get('reason', '')}"
                                                        for e, info in (d.get("physical") or {}).items()))
    candidates = [(name, c["heldout_rms_mm_with_frames"], c["gain_mm"], c["z"], c["n_parameters"]) if c.get("tried")
                  else (name, "not tried", c.get("why", ""), "", "") for name, c in d["candidates"].items()]
    report.add_table(f"Each effect added to frames alone ({source})",
                     ["effect", "held-out RMS", "gain", "paired z", "identifiable parameters"], candidates,
                     units=["", "mm", "mm", "", ""])


def add_iso_tables(report, source: str, iso) -> None:
    """The per-pose ISO 9283 figures of an ``iso9283 evaluate --json`` result."""
    for label, figures in (("as measured", iso), ("predicted after compensation", iso.get("compensated"))):
        if not figures:
            continue
        report.add_table(f"ISO 9283 pose figures, {label} ({source})", ["pose", "n", "AP_P", "AP_x", "AP_y", "AP_z",
                                                                        "RP_l"],
                         [(p.get("pose") or f"P{p['pose_id']}", p["n"], p["ap_mm"], p["ap_x_mm"], p["ap_y_mm"], p["ap_z_mm"],
                           "-" if p["rp_mm"] is None else p["rp_mm"]) for p in figures["poses"]],
                         units=["", "", "mm", "mm", "mm", "mm", "mm"], note=f"measurement frame: {iso.get('frame_fit', '')}")


def _comparison_tables(report, source: str, cmp) -> None:
    rows = []
    for ch in cmp["changes"] + cmp.get("setup_changes", []):
        old, unit = display_value(ch["old"], ch["unit"])
        rows.append((ch["parameter"], unit, old, display_value(ch["new"], ch["unit"])[0],
                     display_value(ch["change"], ch["unit"])[0],
                     "" if ch.get("std_error") is None else display_value(ch["std_error"], ch["unit"])[0],
                     "" if ch.get("z") is None else ch["z"], "YES" if ch.get("significant") else "no"))
    report.add_table(f"Parameters of both campaigns ({source})",
                     ["parameter", "unit", "old", "new", "change", "std error", "z", "beyond"], rows)

