"""Settings files under attack (issues 12 and 22): error-budget configs (YAML/TOML) and
simulation scenarios with values out of range, nesting too deep, YAML alias bombs and keys
given twice.

The rules every test here holds the command to, and the helpers, are in ``hostile.py``.
"""

import pytest
from hypothesis import given, settings, strategies as st

from hostile import assert_one_line, cli_process, run


# ---------------------------------------------------------------------------------------
# Config and scenario files (12: 11, 12, 21)
# ---------------------------------------------------------------------------------------
_DEEP = "[" * 5000 + "]" * 5000


def _short_id(value):
    return value[:40] if isinstance(value, str) else None


@pytest.mark.parametrize("name, text, fragment", [
    ("int-key.yaml", "1: 2\n", "1: keys must be names, not int"),
    ("huge.yaml", "groups:\n  drive:\n    std_m: 1.0e+300\n    std_rad: 0.001\n",
     "groups.drive.std_m: 1e+300 is outside"),
    ("huge.toml", "[groups.drive]\nstd_m = 1e300\nstd_rad = 0.001\n", "groups.drive.std_m: 1e+300 is outside"),
    ("nan.yaml", "groups:\n  drive:\n    std_m: .nan\n    std_rad: 0.001\n", "groups.drive.std_m: expected a finite"),
    ("text.yaml", "groups:\n  drive:\n    std_m: wide\n    std_rad: 0.001\n", "groups.drive.std_m: expected a number"),
    ("deep.yaml", f"name: {_DEEP}\n", "nested too deeply"),
    ("deep.toml", f"name = {_DEEP}\n", "nested too deeply"),
], ids=_short_id)
def test_12_11_bad_config_files_are_one_line(name, text, fragment, tmp_path, capsys):
    path = tmp_path / name
    path.write_text(text)
    code, out, err = run(["montecarlo", "--config", path, "--samples", "100", "--quiet"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, str(path), fragment)


@pytest.mark.parametrize("text, fragment", [
    ("context:\n  payload_fraction: abc\n", "context.payload_fraction: expected a number, got 'abc'"),
    ("context:\n  payload_fraction: null\n", "context.payload_fraction: expected a number, got None"),
    ("context:\n  payload_kg: heavy\n", "context.payload_kg: expected a number"),
    ("context:\n  temperature_c: hot\n", "context.temperature_c: expected a number"),
    ("context: [1]\n", "context: a mapping"),
    ("1: 2\n", "1: keys must be names"),
    (f"noise_mm: {_DEEP}\n", "nested too deeply"),
    ("context:\n  payload_kg: -150\n", "context.payload_kg: -150 is outside"),  # 21
    ("context:\n  temperature_spread_c: -5\n", "context.temperature_spread_c: -5 is outside"),  # 21
    ("effects:\n  geometry:\n    tcp_rms_mm: -1\n", "effects.geometry.tcp_rms_mm: -1 is outside"),  # 21
    ("effects:\n  compliance:\n    options:\n      link_mass_factors: abc\n", "effects.compliance.options"),
], ids=_short_id)
def test_12_12_12_21_bad_scenario_files_are_one_line_and_write_nothing(text, fragment, tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(text if text.startswith("effects") else "effects:\n  geometry: {}\n" + text)
    code, out, err = run(["simulate", "--scenario", path, "--n", "5", "--out", tmp_path / "o.csv"], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, str(path), fragment)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
                    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(
                        st.integers() | st.text(max_size=6), inner, max_size=3), max_leaves=12))
def test_fuzz_any_yaml_value_in_a_scenario_context_is_accepted_or_one_input_error(value):
    import yaml

    from tcr_accuracy.analysis.scenario import scenario_from_dict
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.budget_file import parse_table

    text = yaml.safe_dump({"effects": {"geometry": {}}, "context": {"payload_fraction": value}})
    try:
        scenario_from_dict(parse_table(text, "s.yaml"), source="s.yaml")
    except InputError as exc:
        assert str(exc).startswith("s.yaml: ") and "\n" not in str(exc)


# ---------------------------------------------------------------------------------------
# YAML aliases (a "billion laughs" of nodes) and repeated keys (22: 2, 31)
# ---------------------------------------------------------------------------------------
def alias_bomb() -> str:
    """548 bytes standing for 10^9 nodes: nine levels of aliases, each a list of ten of the previous one."""
    levels = ["      - &a0 [x,x,x,x,x,x,x,x,x,x]"]
    levels += [f"      - &a{i} [" + ",".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, 10)]
    return "groups:\n  link_length:\n    std_m: 0.0001\n    junk:\n" + "\n".join(levels) + "\n"


@pytest.mark.parametrize("argv", [["montecarlo", "--config", "F", "--samples", "100", "--quiet"],
                                  ["simulate", "--scenario", "F", "--n", "5", "--out", "OUT/o.csv"]])
def test_22_02_a_yaml_alias_bomb_is_refused_at_once(argv, tmp_path):
    # in a child process with a timeout: were the bomb walked, the test fails instead of hanging
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(alias_bomb())
    (tmp_path / "out").mkdir()
    result = cli_process([str(bomb) if a == "F" else a.replace("OUT", str(tmp_path / "out")) for a in argv],
                         cwd=tmp_path, timeout=60)
    assert result.returncode == 2 and result.stdout == ""
    assert_one_line(result.stderr, f"{bomb}: line 6: YAML aliases (*a0) are refused")
    assert list((tmp_path / "out").iterdir()) == []


@pytest.mark.parametrize("text, line, key", [
    ("groups:\n  drive:\n    std_m: 0.001\n    std_rad: 0.001\n    std_m: 0.002\n", 5, "std_m"),
    ("groups:\n  drive: {std_m: 0.001, std_rad: 0.001}\ngroups: {}\n", 3, "groups"),
])
def test_22_31_a_key_given_twice_is_refused(text, line, key, tmp_path, capsys):
    path = tmp_path / "dup.yaml"
    path.write_text(text)
    code, out, err = run(["montecarlo", "--config", path, "--samples", "100", "--quiet"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: line {line}: key '{key}' is given twice")


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.sampled_from(["a", "b", "c", "std_m"]), min_size=1, max_size=6))
def test_fuzz_22_31_repeated_keys_are_refused_unique_ones_read(keys):
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.budget_file import parse_table

    text = "t:\n" + "".join(f"  {k}: {i}\n" for i, k in enumerate(keys))
    try:
        data = parse_table(text, "s.yaml")
    except InputError as exc:
        assert len(set(keys)) < len(keys)
        first_repeat = next(i for i, k in enumerate(keys) if k in keys[:i])
        assert str(exc).startswith(f"s.yaml: line {first_repeat + 2}: key '{keys[first_repeat]}'")
        return
    assert len(set(keys)) == len(keys) and data == {"t": {k: i for i, k in enumerate(keys)}}
