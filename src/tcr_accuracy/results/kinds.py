"""Which result a JSON document is: the kinds of result the commands write and the keys that
tell each apart."""

from __future__ import annotations

from ..exceptions import InputError

#: The kinds of JSON result a report reads, and the keys that tell each apart.
KINDS = {
    "diagnosis": ("steps", "selected_effects", "parameters", "noise_floor_mm"),
    "iso9283": ("poses", "summary", "n_readings", "frame"),
    "comparison": ("changes", "tcp_effect", "z_threshold", "old", "new"),
    "export": ("accuracy", "measured_frame", "refit"),  # export's accuracy.json (asbuilt.export_result)
}


def kind_of(doc, source: str) -> str:
    """Which result ``doc`` is ("diagnosis", "iso9283", "comparison", "export"); InputError naming ``source`` if none."""
    if isinstance(doc, dict):
        for kind, keys in KINDS.items():
            if all(k in doc for k in keys):
                return kind
    raise InputError(f"{source}: not a diagnosis, ISO 9283 evaluation, comparison or export result as tcr-accuracy "
                     "writes them; a calibration report is made of those")


def kind_or_none(doc) -> str | None:
    """Which result ``doc`` is, or None when it is none of :data:`KINDS`."""
    try:
        return kind_of(doc, "")
    except InputError:
        return None
