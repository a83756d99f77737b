"""A small blind benchmark: random hidden scenarios, diagnosis on the CSV alone, then the truth."""

import importlib.util
import json

from conftest import REPO


def _benchmark_module():
    spec = importlib.util.spec_from_file_location("blind_benchmark", REPO / "scripts" / "blind_benchmark.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_small_blind_benchmark(tmp_path, capsys):
    bench = _benchmark_module()
    out = tmp_path / "blind.json"
    code = bench.main(["--scenarios", "3", "--n-train", "160", "--n-test", "60", "--folds", "3",
                       "--outside-every", "3", "--seed", "4", "--json", str(out)])
    assert code == 0
    result = json.loads(out.read_text())
    assert {"share_named_right", "median_rms_over_noise", "scenarios"} <= set(result)
    rows = result["scenarios"]
    assert [r["robot"] for r in rows] == ["tool_changer", "ur5", "tool_changer"]
    inside = [r for r in rows if r["in_vocabulary"]]
    outside = [r for r in rows if not r["in_vocabulary"]]
    assert len(inside) == 2 and len(outside) == 1
    for r in inside:
        # judged against the hidden truth: the dominant effect is named, the fitted model
        # predicts unseen measurements to the noise floor, and no structure is claimed
        assert r["named_right"], r
        assert r["test_over_noise"] < 1.5, r
        assert not r["structure_remains"], r
    # an effect outside the vocabulary: the diagnosis must not claim a fit
    assert outside[0]["structure_remains"], outside[0]
    assert outside[0]["test_over_noise"] > 1.5
    assert "share_named_right" in capsys.readouterr().out
