"""The calibration report's technical detail, rebuilt from the JSON results (mm and deg).

After the first page (:mod:`tcr_accuracy.view.calibration_report`), ``tcr-accuracy report``
shows the tables it can rebuild from each result's JSON: a diagnosis' ladder, every fitted
parameter with its standard error, 95 % interval and physical range, the candidates and its
notes; an ISO 9283 test's per-pose figures per test condition; a comparison's parameters of both
campaigns. Every value a person reads is in display units (:func:`tcr_accuracy.units.display_value`);
SI stays in the JSON.
"""

from __future__ import annotations

from ..units import display_value
from ..results.kinds import kind_of


def add_technical_tables(report, campaign, kinds=("diagnosis", "iso9283", "comparison")) -> None:
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


def parameter_rows(d) -> list:
    """Every fitted parameter of a diagnosis' JSON ``d`` (frames last) as (name, value, std, 95 % interval,
    physical range, unit), in display units."""
    effects = [e for e in d["parameters"] if e != "frames"] + [e for e in d["parameters"] if e == "frames"]
    rows = []
    for e in effects:
        physical = (d.get("physical") or {}).get(e, {})
        rows += [_parameter_row(d, e, n, physical) for n in d["parameters"][e]]
    return rows


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


def _diagnosis_tables(report, source: str, d) -> None:
    report.add_table(f"Fitted parameters ({source})", ["parameter", "value", "standard error", "95 % interval",
                                                       "physical range", "unit"], parameter_rows(d),
                     note="display units; standard error from the measurement noise (not model error); 95 % "
                          "interval: value +- 1.96 standard errors within the physical range; frames: the tracker "
                          "frame and the reflector's offset on the tool (the setup). "
                          + "; ".join(f"{e}: {info.get('reason', '')}" for e, info in (d.get("physical") or {}).items()))
    report.add_table(f"How far the gap shrinks ({source}; k-fold held-out, in the order the effects explain it)",
                     ["step", "parameters", "train RMS", "held-out mean", "held-out RMS", "held-out max", "gain",
                      "gain 95 % interval"],
                     [(s["effect"] if i == 0 else "+" + s["effect"], s["n_parameters"], s["train_rms_mm"],
                       s["heldout_mean_mm"], s["heldout_rms_mm"], s["heldout_max_mm"],
                       s.get("gain_heldout_rms_mm", ""),
                       "" if not s.get("gain_interval_mm") else
                       f"{s['gain_interval_mm'][0]:+.4f} to {s['gain_interval_mm'][1]:+.4f}")
                      for i, s in enumerate(d["steps"])], units=["", "", "mm", "mm", "mm", "mm", "mm", "mm"])
    if d.get("families"):
        report.add_table(f"Families of effects ({source})", ["family", "chosen effects", "share", "share 95 % interval"],
                         [(f["family"], ", ".join(f["effects"]), f["share_mm"],
                           f"{f['interval_mm'][0]:+.4f} to {f['interval_mm'][1]:+.4f}") for f in d["families"]],
                         units=["", "", "mm", "mm"],
                         note="share: how much the held-out RMS rises without every member of the family")
    mechanisms = [(m["effect"], m["family"], m["mechanism"], "yes" if m["physical"] else "no", m["check"])
                  for m in d.get("mechanisms") or [] if m["effect"] != "frames"]
    if mechanisms:
        report.add_table(f"What mechanism each chosen effect stands for ({source})",
                         ["effect", "family", "mechanism its fitted sign and size fit", "physical", "check"],
                         mechanisms)
    if d.get("ambiguous"):
        report.add_table(f"What the data cannot tell apart ({source})", ["group", "member", "held-out RMS",
                                                                          "parameters"],
                         [("{" + ", ".join(g["effects"]) + "}", m.get("effect", ""), m.get("heldout_rms_mm", ""),
                           m.get("n_parameters", "")) for g in d["ambiguous"] for m in g.get("members") or [{}]],
                         units=["", "", "mm", ""], note="check on the robot which it is; tcr-accuracy plan-poses "
                                                        "suggests poses that separate them")
    candidates = [(name, c["heldout_rms_mm_with_frames"], c["gain_mm"], c["z"], c["n_parameters"]) if c.get("tried")
                  else (name, "not tried", c.get("why", ""), "", "") for name, c in d["candidates"].items()]
    report.add_table(f"Each effect added to frames alone ({source})",
                     ["effect", "held-out RMS", "gain", "paired z", "identifiable parameters"], candidates,
                     units=["", "mm", "mm", "", ""])
    if d.get("notes"):
        report.add_text("\n\n".join(d["notes"]), heading=f"Notes of the diagnosis ({source})")


def iso_condition_label(block) -> str:
    """"100 % rated load, 50 % rated speed" of an ISO result's block, or "" when it names no condition."""
    condition = block.get("condition") or {}
    parts = [f"{condition[k]:g} % rated {what}" for k, what in (("load_pct", "load"), ("speed_pct", "speed"))
             if condition.get(k) is not None]
    return ", ".join(parts)


def add_iso_tables(report, source: str, iso) -> None:
    """The per-pose ISO 9283 figures of an ``iso9283 evaluate --json`` result, per test condition."""
    for block in iso.get("conditions") or [iso]:
        condition = iso_condition_label(block)
        for label, figures in (("as measured", block), ("predicted after compensation", block.get("compensated"))):
            if not figures:
                continue
            report.add_table(f"ISO 9283 pose figures, {label} ({source}{'; ' + condition if condition else ''})",
                             ["pose", "n", "AP_P", "AP_x", "AP_y", "AP_z", "RP_l"],
                             [(p.get("pose") or f"P{p['pose_id']}", p["n"], p["ap_mm"], p["ap_x_mm"], p["ap_y_mm"],
                               p["ap_z_mm"], "-" if p["rp_mm"] is None else p["rp_mm"]) for p in figures["poses"]],
                             units=["", "", "mm", "mm", "mm", "mm", "mm"],
                             note=f"measurement frame: {block.get('frame_fit', '')}")
    if iso.get("notes"):
        report.add_text("\n\n".join(iso["notes"]), heading=f"Notes of the ISO 9283 test ({source})")


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
