"""Stage 4 (``diagnosis/stages/attribute.py``), second pass (issue 36): the branch no test entered, a primary
effect that cannot be told from a drift in time, on the stand-ins of tests/test_muts_attribute.py. Each test
names a planted change it was seen to catch."""

from __future__ import annotations

import dataclasses

from test_muts_attribute import _attribute

from tcr_accuracy.diagnosis.stages import attribute

WHY = "temperature_c follows the measurement order (r = +0.97): an error growing with it (geometry) cannot be told " \
      "from a drift in time"


def test_a_primary_effect_confounded_with_a_drift_is_not_named(monkeypatch):
    """The rows rank the geometric family and, within it, geometry apart (the primary effect on its own); but
    geometry's reading is confounded with a drift (a temperature that follows the measurement order): the note
    names it and the reason in its words, drift joins the group (in the vocabulary's order), and neither an
    effect nor a family is named. A confounded effect outside the group (compliance) changes nothing. Seen
    failing on the note's string joins ``+`` turned to ``-`` (a TypeError: the branch ran in no test before)."""
    def confounded(reading, confounding):
        return dataclasses.replace(reading, confounded=(WHY,)) if reading.effect == "geometry" else reading

    monkeypatch.setattr(attribute, "_with_confounding", confounded)
    out, _ = _attribute(monkeypatch, ranked_families=True, ranked_own=True)
    assert out.primary_effect is None and out.primary_family is None
    assert out.primary_group == ("geometry", "drift")
    assert out.notes == (f"geometry: cannot be told from a drift in time ({WHY}); not named as the cause: measure "
                         "in an order that does not follow the joints (tcr-accuracy plan-poses writes one)",)

    def elsewhere(reading, confounding):
        return dataclasses.replace(reading, confounded=(WHY,)) if reading.effect == "compliance" else reading

    monkeypatch.setattr(attribute, "_with_confounding", elsewhere)
    out, _ = _attribute(monkeypatch, ranked_families=True, ranked_own=True)
    assert out.primary_effect == "geometry" and out.primary_family == "geometric" and out.notes == ()
