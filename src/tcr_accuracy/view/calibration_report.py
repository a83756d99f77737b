"""The calibration report's first page: what a customer reads and signs, from the JSON results.

Built from the JSON documents the commands write (``diagnose --json``, ``iso9283 evaluate
--json``, ``compare --json``) and the campaign's facts (:mod:`tcr_accuracy.io.campaign`: the
``--campaign`` file and the flags beside it), so that ``diagnose --out`` and ``tcr-accuracy report
DIAGNOSIS.json ISO.json ...`` show the same page with the same numbers::

    campaign = Campaign(robot=RobotFacts.from_documents(docs), documents=[("d.json", doc), ...],
                        files=[("diagnosis JSON", "../d.json")], facts=read_campaign("campaign.yaml"))
    html_fragment, markdown = first_page(campaign, created="2026-11-24 10:00:00 UTC")
    report.set_first_page(html_fragment, markdown)

The page holds, in this order: the title; the identification (customer, robot model and serial,
URDF and TCP frame, instrument with its serial and certificate and the noise the data show,
temperature range, date, operator, data); the result (the TCP error before and after calibration,
k-fold held-out mean / RMS / max, and the ISO 9283 AP and RP of a pose test, each against its
stated limit) with one pass/fail line; what was done; what was found (the family of effects that
causes most of the gap, then per chosen effect its gain, the mechanism its fitted values fit and
the check on the robot; what remains; what changed since an earlier campaign); what to do next
(the ``plan-poses`` command line, the checks, loading the model); the files; the lines to sign.
The fitted parameters, the tables and the plots follow it (:mod:`tcr_accuracy.view.result_tables`,
:mod:`tcr_accuracy.view.plots_results`). Values in display units (mm, deg, deg/kNm, ...:
:data:`tcr_accuracy.units.DISPLAY_UNITS`).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field

from ..exceptions import InputError
from ..io.campaign import CampaignFacts
from ..results.kinds import kind_of
from ..units import display_value
from .accuracy_verdict import TCP_KEYS, accuracy_figures, file_name, form_verdicts, iso_blocks
from .uncertainty_words import budget_blocks, budget_index, export_table, exports_of
from .diagnosis_summary import family_answer
from .next_steps import next_steps
from .page_blocks import PAGE_LINES, Code, Droppable, fit_page, to_html, to_markdown

#: Who signs the report (one column each, with name, signature and date), and the campaign
#: file's key for the name printed there.
SIGNATURES = (("Prepared by", "prepared_by"), ("Checked by", "checked_by"))

#: The significant changes of a comparison page 1 lists at most (all in the technical detail).
FIRST_PAGE_CHANGES = 5

#: Lines of body text (:func:`tcr_accuracy.view.page_blocks.estimated_lines`) page 1 fills at
#: most: chosen effects beyond the first two, the checks to make and the changes beyond the first
#: two are left out, the last first, until the estimate fits (:func:`fit_page`); what the estimate
#: misses, the printed page's own measurement scales away (``view.report``: CSS zoom, at least 0.8).
FIRST_PAGE_LINES = PAGE_LINES


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
        JSON results, each of a kind of :data:`tcr_accuracy.results.kinds.KINDS`, labelled by their file (or command).
    files : list of (label, href)
        Links to the files written with the report (relative to the report folder).
    facts : CampaignFacts
        What the campaign file and flags say: customer, serial, instrument, limits, ...
    """

    robot: RobotFacts
    documents: list
    files: list = field(default_factory=list)
    facts: CampaignFacts = field(default_factory=CampaignFacts)

    def of_kind(self, kind: str) -> list:
        return [(s, d) for s, d in self.documents if kind_of(d, s) == kind]




# ---------------------------------------------------------------------------------------
# The page as blocks (rendered by tcr_accuracy.view.page_blocks)
# ---------------------------------------------------------------------------------------
def first_page(campaign: Campaign, created: str) -> tuple[str, str]:
    """The first page as (HTML fragment, Markdown). ``created``: the report's date line."""
    blocks = page_blocks(campaign, created)
    return to_html(blocks), to_markdown(blocks)


def page_blocks(c: Campaign, created: str) -> list:
    """The first page as a list of blocks (see :mod:`tcr_accuracy.view.page_blocks`)."""
    diagnoses, isos, comparisons = (c.of_kind(k) for k in ("diagnosis", "iso9283", "comparison"))
    d = diagnoses[-1][1] if diagnoses else None
    out: list = [("h1", c.facts.title or f"Calibration report: {c.robot.name}")]
    out.append(("facts", _identification(c, created, d, diagnoses, isos, comparisons)))
    figures = accuracy_figures(d, isos)
    exports = exports_of(c)
    budgets = budget_index(c, d, exports, isos)
    out.append(("h2", "Result"))
    if exports:  # each form the customer receives, with its expanded uncertainty
        out.append(export_table(exports[-1], budgets, c.facts.limits_mm))
        if isos:
            out.append(_result_table([f for f in figures if f.limit_key in ("ap", "rp")], c.facts.limits_mm, None,
                                     isos, budgets))
    else:
        out.append(_result_table(figures, c.facts.limits_mm, d, isos, budgets))
    out += [("verdict", v.status + (f" for {v.form}" if v.form else ""), v.why)
            for v in form_verdicts(d, isos, exports, c.facts.limits_mm)]
    out += budget_blocks(c, d, exports, isos, budgets)
    out.append(("h2", "What was done"))
    out.append(("p", _what_was_done(c, d, diagnoses, isos, comparisons)))
    if d is not None or comparisons:
        out.append(("h2", "What was found"))
        out += _found(d, comparisons)
    out.append(("h2", "What to do next"))
    out.append(("list", _next_steps(c, d, comparisons)))
    if c.files:
        out.append(("links", list(c.files)))
    out.append(("signatures", tuple((role, getattr(c.facts, key)) for role, key in SIGNATURES)))
    return fit_page(out, FIRST_PAGE_LINES)


def _stated(text: str) -> str:
    return text or "not stated"


def _identification(c, created, d, diagnoses, isos, comparisons) -> list:
    """Rows of (label, value, label, value)."""
    r, f = c.robot, c.facts
    kinds = [k for _, k in r.joints]
    joints = (f"{len(kinds)} joints ({', '.join(f'{kinds.count(k)} {k}' for k in dict.fromkeys(kinds))}"
              + (f": {', '.join(j for j, k in r.joints if k == 'prismatic')}" if 0 < kinds.count(
                  "prismatic") < len(kinds) else "") + ")" if r.joints else "joints not recorded in the results")
    robot = (f"{f.robot_model or r.name}, serial {_stated(f.robot_serial)}; URDF: {_urdf_source(r.source)}; "
             f"TCP frame {r.tool_frame}; {joints}")
    instrument = _instrument_text(f, d)
    date = f"measured {f.date}; report {created[:10]}" if f.date else f"{created[:10]} (the report's date)"
    rows = [("Customer", _stated(f.customer), "Date", date),
            ("Robot", robot, "Operator", _stated(f.operator)),
            ("Instrument", instrument, "Temperature", _temperature_text(f, d))]
    return rows


def _instrument_text(f: CampaignFacts, d) -> list:
    spec = (d or {}).get("instrument") or {}
    name = f.instrument_name or spec.get("name") or "not stated"
    lines = [f"{name}, serial {_stated(f.instrument_serial)}; certificate {_stated(f.certificate)}"]
    if f.instrument_mpe_um is not None:
        a, b = f.instrument_mpe_um
        lines.append(f"specified MPE {a:g} um + {b:g} um/m" + (" across the beam, {:g} um + {:g} um/m along it".format(
            *f.instrument_radial_mpe_um) if f.instrument_radial_mpe_um else "") + " (campaign file)")
    elif spec:
        a, b = spec["transverse_mpe_um"]
        ar, br = spec["radial_mpe_um"]
        lines.append(f"specified MPE {a:g} um + {b:g} um/m across the beam, {ar:g} um + {br:g} um/m along it")
    else:
        lines.append("no MPE stated (instrument.mpe_um in the campaign file, or diagnose --instrument)")
    if d is not None:
        noise = d.get("noise") or {}
        how = {"given": "given for the instrument (--noise-mm)",
               "repeated poses": "estimated from repeated readings of the same poses",
               "instrument specification": "from the instrument's specification",
               "residual": "estimated from the final residual (an upper bound: the instrument may be better)",
               "residual nugget": "estimated from the part of the residual that does not vary with the joints"}
        source = noise.get("source", "")
        lines.append(f"noise the data show (not the instrument's specification): {_mm(d.get('tracker_noise_mm'))} mm "
                     f"per axis, noise floor {_mm(d.get('noise_floor_mm'))} mm; {how.get(source, source)}")
    return lines


def _temperature_text(f: CampaignFacts, d) -> str:
    if f.temperature_c is not None:
        return f"{f.temperature_c[0]:.1f} to {f.temperature_c[1]:.1f} degC"
    bins = (((d or {}).get("where") or {}).get("temperature_c") or {}).get("bins") or []
    if bins:
        return f"{bins[0]['low']:.1f} to {bins[-1]['high']:.1f} degC (the measurements' temperature_c column)"
    return "not stated"


def _urdf_source(source: str) -> str:
    if source == "tool_changer":
        return "built-in shield-machine tool-changer (tcr-accuracy)"
    if "/" in source or "\\" in source or source.endswith(".urdf"):
        return file_name(source)  # the file's name: no folder of the user's machine on page 1
    return f"example-robot-data {source}"


def _mm(value) -> str:
    return "-" if value is None else f"{value:.4f}"


def _mm3(value) -> str:
    return "-" if value is None else f"{value:.3f}"


def _result_table(figures, limits_mm: dict, d, isos, budgets=None) -> tuple:
    rows = []
    own = {"mean": ("full model", "k-fold held-out", "mean"), "rms": ("full model", "k-fold held-out", "rms"),
           "max": ("full model", "k-fold held-out", "max"), "ap": None, "rp": None}
    for f in figures:
        limit = limits_mm.get(f.limit_key)
        judged = "-" if limit is None or f.judged_mm is None else ("within" if f.judged_mm <= limit else "OUTSIDE")
        budget = (budgets or {}).get(own.get(f.limit_key)) if f.limit_key in TCP_KEYS else next(
            (b for (form, on, s), b in (budgets or {}).items() if on == "iso" and s == f.limit_key
             and form in f.label), None)
        rows.append((f.label, _mm(f.before_mm), _mm(f.after_mm),
                     "-" if budget is None else f"{budget.expanded * 1e3:.4f}",
                     "-" if limit is None else f"{limit:g}", judged, "mm"))
    note = []
    if d is not None:
        note.append("Held-out: from poses not used in the fit (k-fold cross-validation). Before: the nominal robot "
                    "with only the tracker frame and TCP offset fitted; after: the full model (the form the "
                    "compensation filter carries). U: expanded uncertainty (k = 2) of the judged figure.")
    if isos:
        note.append("ISO 9283: before as measured, after predicted with the diagnosis of iso9283 evaluate --model "
                    "('-': none).")
    if limits_mm:
        note.append("A limit judges the after figure where there is one.")
    if not rows:
        rows.append(("no accuracy figures in these results", "-", "-", "-", "-", "-", ""))
    return ("table", ("figure", "before", "after", "U (k = 2)", "limit", "judged", "unit"), rows, " ".join(note),
            "accuracy")


# ---------------------------------------------------------------------------------------
# What was done, what was found
# ---------------------------------------------------------------------------------------
def _what_was_done(c, d, diagnoses, isos, comparisons) -> str:
    """The data and what was made of them, in a few sentences."""
    said = []
    instrument = c.facts.instrument_name or ((d or {}).get("instrument") or {}).get("name") or "the instrument"
    for source, doc in diagnoses[:-1]:
        said.append(f"Also diagnosed: {file_name(doc.get('measurements', source))} ({doc['n_measurements']} poses).")
    for source, doc in diagnoses[-1:]:
        chosen = [e for e in doc["selected_effects"] if e != "frames"]
        tried = sum(1 for x in (doc.get("candidates") or {}).values() if x.get("tried"))
        sessions = max(len(doc.get("sessions") or []), 1)
        said.append(f"Measured with {instrument} at {doc['n_measurements']} poses in {sessions} session"
                    f"{'s' if sessions > 1 else ''} ({file_name(doc.get('measurements', source))}); tracker frame and TCP offset "
                    f"fitted; of {tried} candidate effects, those lowering the error on held-out poses kept "
                    f"({doc.get('folds')}-fold cross-validation): " + (", ".join(chosen) if chosen else "none")
                    + ("; written out as an as-built URDF and effects file" if doc.get("as_built_urdf") else "") + ".")
    for source, iso in isos:
        blocks = iso_blocks(iso)
        model = (blocks[0].get("compensated") or {}).get("model")
        said.append(f"ISO 9283 pose test {file_name(iso.get('measurements', source))}: "
                    f"{sum(b['n_readings'] for b in blocks)} "
                    f"readings at {len(iso['poses'])} poses" + (f", {len(blocks)} test conditions" if len(blocks) > 1
                                                                else "")
                    + ", as measured" + (f" and predicted after compensation with {file_name(model)}." if model else "."))
    for _, cmp in comparisons:
        said.append(f"Compared with campaign {file_name(cmp['old'])} over {cmp['tcp_effect']['n_poses']} poses (significant "
                    f"beyond {cmp['z_threshold']:g} standard errors).")
    return " ".join(said) or "Nothing: no results were given."


def _found(d, comparisons) -> list:
    out = []
    items = []
    if d is not None:
        answer = family_answer(d.get("families") or [], d.get("primary_family"), d.get("primary_effect"),
                               d.get("primary_group") or [])
        out.append(("p", _sentence(answer) + "."))
        items += _effect_items(d)
        items += [f"The order of measurement: {c['why']}." if c.get("drift_reproduces") and not
                  c.get("confounded_effects") else f"Mind the order of measurement: {c['why']}; tcr-accuracy "
                  "plan-poses writes an order that separates them." for c in d.get("confounding") or []]
        items += [f"Flag: {_sentence(c['text'])}." for c in (d.get("plausibility") or {}).get("checks") or []
                  if c.get("flagged")]
        items += _remains(d)
    if items:
        out.append(("list", items))
    for _, cmp in comparisons:
        out += _changes(cmp)
    return out


def _sentence(text: str) -> str:
    return text[:1].upper() + text[1:]


def _effect_items(d) -> list:
    """One item per chosen effect, the primary family's first: its gain, the mechanism its fitted
    values fit and the check on the robot."""
    steps = {s["effect"]: s for s in d["steps"][1:]}
    order = {f["family"]: i for i, f in enumerate(d.get("families") or [])}
    if d.get("primary_family") in order:
        order[d["primary_family"]] = -1
    frequency = d.get("selection_frequency") or {}
    replays = (d.get("selection") or {}).get("n_replays", 0)
    chosen = [m for m in d.get("mechanisms") or [] if m["effect"] != "frames"]
    chosen.sort(key=lambda m: (order.get(m["family"], len(order)), list(steps).index(m["effect"])
                               if m["effect"] in steps else len(steps)))
    if not chosen:
        return ["No effect beyond the tracker frame and the TCP offset explains the data significantly."]
    items = []
    for k, m in enumerate(chosen):
        e, step = m["effect"], steps.get(m["effect"], {})
        low, high = step.get("gain_interval_mm") or (None, None)
        gain = (f"held-out RMS {_mm3(step.get('gain_heldout_rms_mm'))} mm lower"
                + (f" [95 %: {_mm3(low)}, {_mm3(high)}]" if low is not None else ""))
        stable = f"; chosen in {frequency.get(e, 0.0):.0%} of {replays} replays" if replays else ""
        plausible = (d.get("physical") or {}).get(e, {}).get("plausible", True)
        text = (f"{e} ({m['family']}; {gain}{stable}" + ("" if plausible else "; OUTSIDE its physical range")
                + "): " + m["mechanism"] + ("" if m["physical"] else " (no known mechanism fits most of it)") + "."
                + "".join(f" Assumed: {a}." for a in m.get("assumed") or [])
                + (f" Check: {m['check']}." if m.get("check") else ""))
        items.append(text if k < 2 else Droppable(text, "effect", e))  # the two that explain most stay on the page
    return items


def _remains(d) -> list:
    last = d["steps"][-1]
    noise = d.get("noise") or {}
    floor = d.get("noise_floor_mm")
    ratio = last["heldout_rms_mm"] / floor if floor else float("nan")
    verdict_ = d.get("structure_verdict") or ("yes" if d.get("structure_remains") else "no")
    said = {"yes": "YES: the residual still varies with the joints, so an effect the model lacks is in the data",
            "no": "no: what is left looks like measurement scatter",
            "cannot tell": f"cannot tell with {d['n_measurements']} poses"}.get(verdict_, verdict_)
    items = [f"What remains: held-out RMS {_mm(last['heldout_rms_mm'])} mm = {ratio:.2f} x the noise floor "
             f"{_mm(floor)} mm" + ("" if noise.get("independent", True) else
                                   " (the floor is estimated from this residual: an upper bound)")
             + f"; structure left in the residual: {said}."]
    scatter = d.get("extra_scatter") or {}
    if scatter.get("detected"):
        items.append("Random scatter beyond the instrument: YES (play, clearance).")
    described = {m["effect"] for m in d.get("mechanisms") or []}  # their words say it already
    items += [Droppable(f"{finding.get('description', '')}", "finding") for finding in d.get("outside_physics") or []
              if finding.get("effect") not in described]
    return items


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
    rows.sort(key=lambda r: -abs(float(r[4])) if r[4] != "-" else 0.0)
    tcp = cmp["tcp_effect"]
    text = (f"Since the earlier campaign ({cmp['old']}): {len(rows)} of {len(cmp['changes'])} robot parameters "
            f"changed beyond {cmp['z_threshold']:g} standard errors; on the TCP over {tcp['n_poses']} poses the "
            f"significant changes move it by mean {_mm(tcp['significant_changes']['mean_mm'])} mm, max "
            f"{_mm(tcp['significant_changes']['max_mm'])} mm (all changes: max {_mm(tcp['all_changes']['max_mm'])} mm)."
            + (f" The {FIRST_PAGE_CHANGES} largest below, all in the technical detail." if len(rows) >
               FIRST_PAGE_CHANGES else ""))
    if not rows:
        return [("p", text)]
    shown = [row if k < 2 else Droppable(row, "change", row[0]) for k, row in enumerate(rows[:FIRST_PAGE_CHANGES])]
    return [("p", text), ("table", ("parameter", "old", "new", "change +- std error", "z", "unit"), shown, "",
                          "changes")]


# ---------------------------------------------------------------------------------------
# What to do next
# ---------------------------------------------------------------------------------------
def _next_steps(c: Campaign, d, comparisons) -> list:
    """One sentence a step (view/next_steps.py): the next poses, the checks on the robot (left out
    first when the page is full), loading the calibration."""
    items = []
    if d is not None:
        files = [file_name(f) for f in str(d.get("measurements", "MEASUREMENTS.csv")).split(",") if f.strip()]
        for step in next_steps(d, measurements=files, robot_options=_robot_options(c.robot)):
            items.append(Droppable(step.parts, "check") if step.kind == "check" else step.parts)
    else:
        items.append(("To calibrate, measure the robot at 100 or more poses spread over the joint ranges and run ",
                      Code(f"tcr-accuracy diagnose MEASUREMENTS.csv{_robot_options(c.robot)} --json diagnosis.json"),
                      "; then gather the results: ", Code("tcr-accuracy report diagnosis.json ... --out report")))
    for _, cmp in comparisons:
        for name in cmp.get("significant") or []:
            items.append(Droppable(f"Check on the robot what changed {name} between the campaigns (beyond both fits' "
                                   "uncertainty).", "check"))
    if d is not None:
        items += _calibration_forms(d, c)
    return items


def _calibration_forms(d, c: Campaign) -> list:
    """How to carry the calibration to the robot: the forms and what they reach (the calibration
    URDF's figures where the diagnosis wrote it, the full model's k-fold held-out figure)."""
    from .as_built_summary import urdf_phrase

    sources = [s for s, _ in c.of_kind("diagnosis")]
    path = file_name(sources[-1]) if sources and str(sources[-1]).endswith(".json") else "DIAGNOSIS.json"
    as_built = d.get("as_built") if isinstance(d.get("as_built"), dict) else {}
    urdf = urdf_phrase(as_built.get("accuracy") or [])
    steps = d.get("steps") or []
    final = steps[-1].get("heldout_mean_mm") if steps and isinstance(steps[-1], dict) else None
    full = f" ({final:.4f} mm mean k-fold held-out)" if isinstance(final, float) else ""
    return [(f"Load the calibration into the controller{': ' + urdf if urdf else ''}. ",
             Code(f"tcr-accuracy export {shlex.quote(str(path))} --to calibration"),
             " writes it as a URDF (the TCP frame unchanged, the measured point a frame of its own), DH tables, the UR "
             f"driver's calibration file and a compensation filter that carries the full model{full}, each with "
             "what it reaches.")]


def _robot_options(robot: RobotFacts) -> str:
    if robot.source in ("tool_changer", "", "not recorded"):
        return ""
    return f" --robot {shlex.quote(file_name(robot.source))} --tool {shlex.quote(robot.tool_frame)}"

