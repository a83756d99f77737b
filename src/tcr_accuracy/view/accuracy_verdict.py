"""The result of a calibration report: its figures before and after calibration, against the stated limits.

A figure (:class:`AccuracyFigure`) is what a limit of the campaign file (``limits_mm``, see
:mod:`tcr_accuracy.io.campaign`) judges: a diagnosis' k-fold held-out mean, RMS and max of the
TCP position error, an ISO 9283 test's largest AP_P and RP_l over its poses and test conditions.
:func:`verdict` gives the one line the first page prints: PASS, FAIL, INCOMPLETE (a limit with no
figure to judge) or NOT JUDGED (no limit stated). A limit judges the figure after calibration
where there is one (for an ISO test, as predicted with the diagnosis given to ``iso9283 evaluate
--model``), else the figure as measured.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..io.campaign import LIMIT_FIGURES


def _mm(value) -> str:
    return "-" if value is None else f"{value:.4f}"


@dataclass(frozen=True)
class AccuracyFigure:
    """A figure of the result: before and after calibration [mm], and the limit key it answers to."""

    limit_key: str  # a key of tcr_accuracy.io.campaign.LIMIT_FIGURES
    label: str
    before_mm: float | None
    after_mm: float | None
    predicted: bool = False  # the after figure is predicted, not measured on held-out poses

    @property
    def judged_mm(self) -> float | None:
        """What a limit judges: the figure after calibration, else as measured."""
        return self.after_mm if self.after_mm is not None else self.before_mm


def iso_blocks(iso) -> list:
    """An ISO result's blocks, one per test condition (the result itself when it has one)."""
    return list(iso.get("conditions") or [iso])


def accuracy_figures(d, isos) -> list:
    """The figures of the result (:class:`AccuracyFigure`): the diagnosis' k-fold held-out mean, RMS and
    max of the TCP position error (before: only the tracker frame and TCP offset fitted; after: the
    calibrated model), and per ISO pose test its largest AP_P and RP_l over the poses and conditions
    (after: predicted with the diagnosis given to ``iso9283 evaluate --model``)."""
    out = []
    if d is not None:
        first, last = d["steps"][0], d["steps"][-1]
        for what, key in (("mean", "heldout_mean_mm"), ("RMS", "heldout_rms_mm"), ("max", "heldout_max_mm")):
            out.append(AccuracyFigure(what.lower(), f"TCP position error, held-out {what}", first[key], last[key]))
    for source, iso in isos:
        blocks = iso_blocks(iso)
        name = iso.get("measurements", source)
        where = f"{len(iso['poses'])} poses" + (f" x {len(blocks)} conditions" if len(blocks) > 1 else "")
        after = [(b.get("compensated") or {}).get("summary") for b in blocks]
        for key, label, name_key in (("ap", "ISO 9283 pose accuracy AP_P", "ap_max_mm"),
                                     ("rp", "ISO 9283 repeatability RP_l", "rp_max_mm")):
            before = max(b["summary"][name_key] for b in blocks)
            predicted = None if None in after else max(a[name_key] for a in after)
            out.append(AccuracyFigure(key, f"{label}, largest of {where} ({name}"
                                      + ("; after: predicted)" if predicted is not None else ")"), before, predicted,
                                      predicted is not None))
    return out


#: The limits that judge a form's TCP position error, and those that judge an ISO 9283 pose test.
TCP_KEYS, ISO_KEYS = ("mean", "rms", "max"), ("ap", "rp")
#: What each exported form is for the customer (the export's form names).
FORM_WORDS = {"full model": "the full model through the compensation filter", "URDF alone": "the calibration URDF",
              "UR calibration file": "the UR driver's calibration file"}
#: How each kind of figure is said: on which poses.
ON_WORDS = {"k-fold held-out": "k-fold held-out", "held-out": "on the held-out poses",
            "measured": "on the measured poses"}


@dataclass(frozen=True)
class FormVerdict:
    """The verdict on one form the customer receives (or on an ISO 9283 test).

    form : its words and file ("the calibration URDF (as_built.urdf)"); status : PASS, FAIL,
    INCOMPLETE or NOT JUDGED; why : the figures that decide it.
    """

    form: str
    status: str
    why: str

    @property
    def line(self) -> str:
        """``STATUS for FORM: why`` (the printed ``Result:`` line)."""
        return f"{self.status}{' for ' + self.form if self.form else ''}: {self.why}"


def form_groups(export) -> list[tuple[list, list]]:
    """The export's judged forms (the nominal left out) grouped where their figures agree to 0.1 um
    (the URDF, the UR file and the DH tables carry one geometry): [(form records' names and files,
    the first form's records)]."""
    groups: list = []
    for form in export.forms():
        if form == "nominal":
            continue
        records = export.figures(form)
        key = [(r.on, round(r.mean * 1e7), round(r.max * 1e7)) for r in records]
        for names, first, k in groups:
            if k == key:
                names.append((form, records[0].file))
                break
        else:
            groups.append(([(form, records[0].file)], records, key))
    return [(names, records) for names, records, _ in groups]


def form_name(names) -> str:
    """Words for a group of forms: ``the calibration URDF (as_built.urdf), the UR driver's ...``."""
    words = [f"{FORM_WORDS.get(f, 'the ' + f)}" + (f" ({file})" if file else "") for f, file in names
             if not f.endswith(" table")]
    tables = [file for f, file in names if f.endswith(" table")]
    if tables:
        words.append(f"the DH table{'s' if len(tables) > 1 else ''} ({', '.join(tables)})")
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def form_verdicts(d, isos, exports, limits_mm: dict) -> list[FormVerdict]:
    """One :class:`FormVerdict` per form the customer receives (the export's, grouped where their
    figures agree; without an export the full model on the diagnosis' k-fold figures, and a line
    saying the delivered files were not judged), one per ISO 9283 test, and one INCOMPLETE line
    for a limit no figure answers."""
    if not limits_mm:
        return [FormVerdict("", "NOT JUDGED", "no limit is stated (limits_mm in the campaign file, or --limit-mm)")]
    tcp = {k: v for k, v in limits_mm.items() if k in TCP_KEYS}
    out = []
    if exports:
        for names, records in form_groups(exports[-1]):
            figures = [AccuracyFigure(key, f"{key} {ON_WORDS.get(r.on, r.on)} ({r.n} poses)", None,
                                      getattr(r, key) * 1e3) for r in records for key in TCP_KEYS]
            out.append(FormVerdict(form_name(names), *(verdict(figures, tcp) if tcp else _no_tcp_limit())))
    elif d is not None:
        last = d["steps"][-1]
        figures = [AccuracyFigure(key, f"{key} k-fold held-out ({d['n_measurements']} poses)", None,
                                  last[f"heldout_{key}_mm"]) for key in TCP_KEYS]
        out.append(FormVerdict("the full model through the compensation filter (k-fold held-out)",
                               *(verdict(figures, tcp) if tcp else _no_tcp_limit())))
        out.append(FormVerdict("the calibration URDF and the controller files", "NOT JUDGED",
                               "no export result given (tcr-accuracy export DIAGNOSIS.json --to DIR, then give "
                               "DIR/accuracy.json to report)"))
    iso = {k: v for k, v in limits_mm.items() if k in ISO_KEYS}
    for source, doc in isos if iso else ():
        pair = accuracy_figures(None, [(source, doc)])
        form = ("the full model, predicted for the ISO 9283 test" if pair[0].predicted else
                "the robot as measured in the ISO 9283 test") + f" ({file_name(doc.get('measurements', source))})"
        out.append(FormVerdict(form, *verdict(pair, iso)))
    judged = set(TCP_KEYS) if (exports or d is not None) else set()
    judged |= set(ISO_KEYS) if isos else set()
    missing = [k for k in limits_mm if k not in judged]
    if missing:
        out.append(FormVerdict("", "INCOMPLETE", "no figure in these results for " + "; ".join(
            f"the limit on {LIMIT_FIGURES[k]} ({limits_mm[k]:g} mm)" for k in missing)))
    return out


def file_name(path) -> str:
    """A file's name without its folder (page 1 names no folder of the user's machine); several
    files, comma-separated, each by its name."""
    return ", ".join(str(p).strip().replace("\\", "/").rsplit("/", 1)[-1] for p in str(path).split(","))


def _no_tcp_limit() -> tuple[str, str]:
    return "NOT JUDGED", "no limit on the TCP position error is stated"


def verdict(figures, limits_mm: dict) -> tuple[str, str]:
    """(status, why): PASS when every figure with a stated limit is within it, FAIL when one is
    above it, else why it is not judged. A limit is judged on the figure after calibration."""
    if not limits_mm:
        return "NOT JUDGED", "no limit is stated (limits_mm in the campaign file, or --limit-mm)"
    outside, within = [], []
    figures = [f for f in figures if f.judged_mm is not None]  # an RP of poses read once: no figure
    for key, limit in limits_mm.items():
        for f in (f for f in figures if f.limit_key == key):
            (outside if f.judged_mm > limit else within).append((f, limit))
    missing = [k for k in limits_mm if not any(f.limit_key == k for f in figures)]

    if outside:
        return "FAIL", "; ".join(f"{f.label}: {_mm(f.judged_mm)} mm{' (predicted)' if f.predicted else ''} > "
                                 f"{limit:g} mm" for f, limit in outside)
    if missing:
        return "INCOMPLETE", (("no figure within a limit" if not within else "1 figure within its limit"
                               if len(within) == 1 else f"{len(within)} figures within their limits")
                              + ", but no figure in these results for "
                              + "; ".join(f"the limit on {LIMIT_FIGURES[k]} ({limits_mm[k]:g} mm)" for k in missing))
    return "PASS", ("the figure with a stated limit is within it" if len(within) == 1 else
                    f"all {len(within)} figures with a stated limit are within them")
