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


def verdict(figures, limits_mm: dict) -> tuple[str, str]:
    """(status, why): PASS when every figure with a stated limit is within it, FAIL when one is
    above it, else why it is not judged. A limit is judged on the figure after calibration."""
    if not limits_mm:
        return "NOT JUDGED", "no limit is stated (limits_mm in the campaign file, or --limit-mm)"
    outside, within = [], []
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
