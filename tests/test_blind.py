"""A small blind benchmark: random hidden scenarios, diagnosis on the CSV alone, then the truth.

``scripts/blind_benchmark.py`` runs as a user runs it, in its own interpreter: it draws
each scenario's hidden effects, writes the measurements to a CSV, diagnoses that file
alone, and only then reads the truth. The test judges its JSON by what the benchmark
promises (docs/diagnosis.md and docs/benchmarks.md): the hidden dominant effect is named and the fitted model
reaches the noise floor when every hidden effect is in the vocabulary; structure is
flagged when an effect outside the vocabulary is hidden.
"""

import json
import os
import subprocess
import sys

from conftest import REPO

SCENARIOS, OUTSIDE_EVERY = 3, 3


def test_small_blind_benchmark(tmp_path):
    out = tmp_path / "blind.json"
    done = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "blind_benchmark.py"), "--scenarios", str(SCENARIOS),
         "--n-train", "160", "--n-test", "60", "--folds", "3", "--outside-every", str(OUTSIDE_EVERY),
         "--seed", "4", "--json", str(out)],
        capture_output=True, text=True, cwd=tmp_path, timeout=600,
        env={**os.environ, "PYTHONPATH": str(REPO / "src")})
    assert done.returncode == 0, done.stderr
    assert "share_named_right" in done.stdout  # the printed summary
    rows = json.loads(out.read_text())["scenarios"]
    assert len(rows) == SCENARIOS
    inside = [r for r in rows if not r["outside_vocabulary"]]
    outside = [r for r in rows if r["outside_vocabulary"]]
    assert len(outside) == SCENARIOS // OUTSIDE_EVERY and inside  # --outside-every was applied
    for r in rows:
        # the truth really hid what the row says (dominant and outside effects among the hidden)
        assert r["dominant"] in r["hidden"] and set(r["outside_vocabulary"]) <= set(r["hidden"]), r
    for r in inside:
        # judged against the hidden truth: the dominant effect is named, the fitted model
        # predicts the unseen test rows to the noise floor, and no structure is claimed
        assert r["primary_effect"] == r["dominant"], r
        assert r["test_over_noise"] < 1.5, r
        assert not r["structure_remains"], r
    for r in outside:
        # an effect outside the vocabulary: no model reaches the noise floor and the
        # diagnosis says so instead of claiming a fit
        assert r["test_over_noise"] > 1.5, r
        assert r["structure_remains"], r
