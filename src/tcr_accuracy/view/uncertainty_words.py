"""The calibration report's words on each delivered form and on its measurement uncertainty.

Page 1 (:mod:`tcr_accuracy.view.calibration_report`) shows, from these blocks: the figures of
each form the customer receives (with an export's result) with their expanded uncertainty, one
verdict line per form, the uncertainty budget of the figures that decide the verdicts (each
contribution, its standard uncertainty and how it was obtained), the method and the standard's
clauses followed, the instrument's traceability and the conditions the results apply to. The
technical detail gets every figure's budget and every parameter's (:func:`add_budget_tables`).
The numbers come from :mod:`tcr_accuracy.results.budgets`; here only words. Lengths in mm.
"""

from __future__ import annotations

from ..asbuilt.export_result import ExportResult
from ..results.budgets import SOURCES, figure_budgets, instrument_mpe, parameter_budgets
from ..units import display_value
from .accuracy_verdict import ON_WORDS, TCP_KEYS, file_name, form_groups, form_name
from .page_blocks import Droppable

#: The clauses a report's figures follow.
METHOD = ("Method: error = |measured point - model| after a rigid tracker-frame fit; k-fold: poses left out of the "
          "fit; ISO 9283:1998 7.2.1 (AP), 7.2.2 (RP); uncertainty per GUM, JCGM 100:2008 (4.2, 4.3.7, 5.1.2, 6.2.1).")


#: How each contribution is obtained, in a few words (the figures it was computed from in the technical detail).
BRIEF_HOW = {"instrument MPE": "(a + b L) / sqrt 3 at the distance L from the tracker",
             "measurement noise": "the data's scatter, / sqrt N for a mean",
             "frame registration": "the fitted frame, first order",
             "temperature": "expansion over the range at the reach, / sqrt 12",
             "fit": "sigma sqrt(p / m)"}


def exports_of(campaign) -> list[ExportResult]:
    """The campaign's export results, as typed objects (the last is the one judged)."""
    return [ExportResult.from_dict(doc) for _, doc in campaign.of_kind("export")]


def budget_index(campaign, d, exports, isos) -> dict:
    """(form, on, statistic) -> UncertaintyBudget of every judged figure."""
    return {(w["form"], w["on"], w["statistic"]): b for w, b in figure_budgets(d, exports, isos, campaign.facts)}


def _pm(value_m: float, budget) -> str:
    return f"{value_m * 1e3:.4f}" + ("" if budget is None else f" ± {budget.expanded * 1e3:.3f}")


def export_table(export: ExportResult, budgets: dict, limits_mm: dict) -> tuple:
    """Page 1's result table with an export: per form (grouped where they agree) and poses, mean,
    RMS and max ± U (k = 2), the nominal robot first, the stated limits last."""
    rows = []
    nominal = export.figures("nominal")
    several = len({r.on for r in export.accuracy}) > 1
    for r in nominal:  # the measured poses' rows may leave page 1 for room where held-out ones are there
        row = (f"nominal robot, {ON_WORDS.get(r.on, r.on)} ({r.n}, {file_name(r.data)})",
               f"{r.mean * 1e3:.4f}", f"{r.rms * 1e3:.4f}", f"{r.max * 1e3:.4f}", "mm")
        rows.append(Droppable(row, "row", "nominal robot on the measured poses") if r.on == "measured" and several
                    else row)
    for names, records in form_groups(export):
        first = names[0][0]
        rows.append(("group", form_name(names)))
        for r in records:
            cells = [_pm(getattr(r, s), budgets.get((first, r.on, s))) for s in TCP_KEYS]
            row = (f"{ON_WORDS.get(r.on, r.on)} ({r.n} poses, {file_name(r.data)})", *cells, "mm")
            rows.append(Droppable(row, "row", f"{first} on the measured poses") if r.on == "measured" and len(
                records) > 1 and first == "full model" else row)
    if any(k in limits_mm for k in TCP_KEYS):
        rows.append(("stated limit", *(f"{limits_mm[k]:g}" if k in limits_mm else "-" for k in TCP_KEYS), "mm"))
    note = ("± : expanded uncertainty, k = 2 (budget below). Nominal: the nominal robot with the tracker frame and "
            "TCP offset fitted to the measured poses (the figure export, predict and compensate print). Each form "
            "gets its own tracker frame, fitted on the measured poses; held-out poses were not fitted to.")
    return ("table", ("TCP position error", "mean", "RMS", "max", "unit"), rows, note, "accuracy")


def headline_budgets(budgets: dict, limits_mm: dict, exports, d) -> list:
    """The budgets page 1 lists in full: per judged form the figure that decides its verdict (the
    largest against its limit; without a limit the mean on the best poses there are), per ISO test its AP."""
    chosen = []
    keys = [k for k in TCP_KEYS if k in limits_mm] or ["mean"]
    groups = [(names[0][0], [r.on for r in records]) for names, records in form_groups(exports[-1])] if exports else \
        ([("full model", ["k-fold held-out"])] if d is not None else [])
    for form, ons in groups:
        candidates = [budgets[(form, on, k)] for on in ons for k in keys if (form, on, k) in budgets]
        if candidates:
            limit = {b: limits_mm.get(k, 1.0) for on in ons for k in keys for b in [budgets.get((form, on, k))] if b}
            chosen.append(max(candidates, key=lambda b: b.value / limit[b]))
    chosen += [b for (form, on, s), b in budgets.items() if on == "iso" and s == "ap"]
    return chosen[:3]


def budget_blocks(campaign, d, exports, isos, budgets: dict) -> list:
    """Page 1's measurement uncertainty: the budget table, and the method, traceability and conditions."""
    shown = headline_budgets(budgets, campaign.facts.limits_mm, exports, d)
    out: list = [("h2", "Measurement uncertainty")]
    if shown:
        columns = ("contribution (type): how", *(b.figure for b in shown))
        rows = []
        for source in SOURCES:
            lines = [next((c for c in b.contributions if c.source == source), None) for b in shown]
            first = next((c for c in lines if c is not None), None)
            if first is None:
                continue
            rows.append((f"{source} ({first.evaluation}): {BRIEF_HOW[source]}",
                         *("-" if c is None or c.standard_uncertainty is None else f"{c.standard_uncertainty * 1e3:.4f}"
                           for c in lines)))
        rows.append(("expanded U (k = 2) = 2 x root sum of squares", *(f"{b.expanded * 1e3:.4f}" for b in shown)))
        left = sorted({s for b in shown for s in b.not_evaluated})
        note = ("Standard uncertainties [mm]; A: from the data's scatter, B: from a specification or stated range; "
                "'-': not evaluated" + (f" (left out of U: {', '.join(left)})" if left else "")
                + ". Every figure's and parameter's budget, and what each line was computed from, in the technical "
                "detail.")
        out.append(("table", columns, rows, note, "budget"))
    out.append(("p", METHOD + " " + traceability(campaign, d) + " " + conditions(campaign, d), "note"))
    return out


def traceability(campaign, d) -> str:
    f = campaign.facts
    mpe = instrument_mpe(f, d)
    name = f.instrument_name or ((d or {}).get("instrument") or {}).get("name") or "the instrument"
    said = (f"Traceability: {name}" + (f", serial {f.instrument_serial}" if f.instrument_serial else "")
            + (f", certificate {f.certificate}" if f.certificate else ", no calibration certificate stated")
            + (f"; {mpe[2]}." if mpe else "; no MPE stated: the instrument's own error is not in the budget."))
    return said


def conditions(campaign, d) -> str:
    f = campaign.facts
    serial = f" (serial {f.robot_serial})" if f.robot_serial else ""
    temperature = (f"{f.temperature_c[0]:.1f} to {f.temperature_c[1]:.1f} degC" if f.temperature_c else
                   "the temperature of the measurements (not stated)")
    payload = f"{f.payload_kg:g} kg payload" if f.payload_kg is not None else "the payload carried while measured " \
                                                                              "(not stated)"
    poses = f", over the {d['n_measurements']} measured poses' workspace" if d is not None else ""
    return f"The results apply to this robot{serial} in these conditions: {temperature}, {payload}{poses}."


def add_budget_tables(report, campaign) -> None:
    """The technical detail's budgets: every judged figure's contributions, every parameter's U (k = 2)."""
    diagnoses, isos = campaign.of_kind("diagnosis"), campaign.of_kind("iso9283")
    d = diagnoses[-1][1] if diagnoses else None
    exports = exports_of(campaign)
    grouped = {names[0][0] for names, _ in form_groups(exports[-1])} if exports else None
    budgets = [(w, b) for w, b in figure_budgets(d, exports, isos, campaign.facts)
               if grouped is None or w["on"] == "iso" or w["form"] in grouped]  # one of forms that agree
    if budgets:
        rows = [(b.figure, f"{b.value * 1e3:.4f}", *("-" if c.standard_uncertainty is None else
                                                   f"{c.standard_uncertainty * 1e3:.4f}" for c in b.contributions),
                 f"{b.combined * 1e3:.4f}", f"{b.expanded * 1e3:.4f}") for _, b in budgets]
        report.add_table("Uncertainty budget of every judged figure",
                         ["figure", "value", *(f"u {s}" for s in SOURCES), "u_c", "U (k = 2)"], rows,
                         note="mm; standard uncertainties, '-' not evaluated; GUM (JCGM 100:2008): combined as the root "
                              "sum of squares (5.1.2), expanded with k = 2 (6.2.1)")
        how = {}
        for _, b in budgets:
            for c in b.contributions:
                how.setdefault((c.source, b.figure.split(",")[0]), (c.evaluation, c.how))
        report.add_table("How each contribution was obtained", ["contribution", "for", "type", "how"],
                         [(source, what, *pair) for (source, what), pair in sorted(
                             how.items(), key=lambda kv: SOURCES.index(kv[0][0]))])
    params = parameter_budgets(d, campaign.facts)
    if params:
        rows = []
        for effect, values in params.items():
            for name, b in values.items():
                value, unit = display_value(b.value, b.unit)
                u = [display_value(c.standard_uncertainty, b.unit)[0] if c.standard_uncertainty is not None else None
                     for c in b.contributions]
                rows.append((name, f"{value:+.4g}", *("-" if x is None else f"{x:.2g}" for x in u),
                             f"{display_value(b.expanded, b.unit)[0]:.2g}", unit))
        report.add_table("Uncertainty of each fitted parameter",
                         ["parameter", "value", "u fit", "u instrument MPE", "U (k = 2)", "unit"], rows,
                         note="u fit: the standard error from the fit's covariance; u instrument MPE: the MPE at the "
                              "RMS distance propagated as the fit propagates its scatter; U = 2 sqrt(sum u^2)")
