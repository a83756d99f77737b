"""The structure verdict's words (``diagnosis/structure.py``) where the power probe's record lacks its largest
probed size: said as 0 mm, written out here. Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

from tcr_accuracy.diagnosis.structure import structure_verdict


def test_a_blind_probe_without_its_largest_size_is_said_at_zero_mm():
    """A power record that saw no probed leftover and holds no ``largest_probed_mm``: "cannot tell" where the
    scatter was not tested, "no" where it was and nothing is beyond the noise, each naming 0 mm and the poses.
    Seen failing on ``power.get('largest_probed_mm', 0)`` turned to ``1``."""
    power = {"smallest_detectable_mm": None, "n_poses": 30}
    blind = "the test saw none of the probed leftovers even at 0 mm"
    assert structure_verdict({"remains": False}, power, {"tested": False}, 1e-5, 2e-5) == {
        "verdict": "cannot tell", "reason": f"{blind} with 30 poses"}
    assert structure_verdict({"remains": False}, power, {"tested": True, "detected": False}, 1e-5, 2e-5) == {
        "verdict": "no", "reason": f"no scatter beyond the noise to explain ({blind})"}
