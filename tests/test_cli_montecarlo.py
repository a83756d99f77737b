"""tcr-accuracy montecarlo: JSON keys and units, config files, one-line bad-input errors."""

import json

import numpy as np
import pytest

from tcr_accuracy.io.budget_file import load_budget_file
from tcr_accuracy.cli import main
from tcr_accuracy.model.errors import seed_budget
from tcr_accuracy.analysis.reliability import first_order


def _run(capsys, argv):
    code = main(["montecarlo"] + argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_json_keys_units_and_first_order_agreement(tmp_path, capsys, tool_changer):
    out = tmp_path / "mc.json"
    code, _, _ = _run(capsys, ["--preset", "table2", "--samples", "20000", "--quiet", "--json", str(out),
                               "--tol", "5", "20", "--tail-samples", "5000", "--plots", str(tmp_path / "plots")])
    assert code == 0
    data = json.loads(out.read_text())
    assert set(data["stats_mm"]) == {"dx", "dy", "dz", "dp", "norm"}
    assert set(data["stats_rad"]) == {"d_alpha_z", "d_beta_y", "d_gamma_x"}
    for entry in list(data["stats_mm"].values()) + list(data["stats_rad"].values()):
        assert set(entry) == {"mean", "std", "max", "min"} and entry["min"] <= entry["mean"] <= entry["max"]
    assert set(data["reliability_position"]) == {"5", "20"}
    assert data["samples"] == 20000 and data["seed"] == 0 and data["preset"] == "table2"
    assert data["q"]["j2"] == pytest.approx(30.0)
    # units: mm in stats_mm, against the first-order std computed here in SI
    fo = first_order(seed_budget(tool_changer, "table2"), tool_changer.working_pose)
    np.testing.assert_allclose([data["stats_mm"][k]["std"] for k in ("dx", "dy", "dz")],
                               fo.position_std * 1e3, rtol=0.03)
    np.testing.assert_allclose(data["stats_rad"]["d_alpha_z"]["std"], fo.euler_std[0], rtol=0.03)
    # with std ~8.9 mm per axis, P(|dP| < 20 mm) is large and P(|dP| < 5 mm) small
    assert 0.8 < data["reliability_position"]["20"] < 0.99
    assert data["reliability_position"]["5"] < 0.2
    assert data["stats_mm"]["norm"]["min"] >= 0 and data["stats_mm"]["dp"]["min"] < 0
    tail = data["tail_position"]["20"]
    assert tail["monte_carlo_ci95"][0] <= tail["monte_carlo"] <= tail["monte_carlo_ci95"][1]
    assert abs(tail["first_order"] - tail["monte_carlo"]) < 0.02
    assert sorted(p.rsplit("/", 1)[-1] for p in data["plots"]) == ["cloud_3d.png", "projection_density.png"]
    for p in data["plots"]:
        with open(p, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_printed_table_has_the_seed_rows(capsys):
    code, out, _ = _run(capsys, ["--preset", "clearance", "--samples", "2000", "--quiet"])
    assert code == 0
    for label in ("dp [mm]", "dx [mm]", "|dP| [mm]", "d_alpha (z) [rad]", "P(|dP| < 0.25 mm)"):
        assert label in out


def test_config_file_groups_and_parameters_build_the_stated_budget(tmp_path, tool_changer):
    toml = tmp_path / "budget.toml"
    toml.write_text('[groups.link_length]\nstd_mm = 0.2\n\n[groups.drive]\nstd_deg = 0.5\nstd_mm = 0.3\n\n'
                    '[parameters."j3.dy"]\ndistribution = "uniform"\nlow_mm = -0.1\nhigh_mm = 0.3\n')
    budget = load_budget_file(toml, tool_changer)
    em = budget.error_model
    cov = budget.parameter_covariance()
    assert cov[em.index("j2.drive"), em.index("j2.drive")] == pytest.approx(np.radians(0.5) ** 2)
    assert cov[em.index("j4.drive"), em.index("j4.drive")] == pytest.approx(0.3e-3**2)
    # j3's link runs along its y axis: the 0.2 mm link-length normal plus the 0.4 mm wide uniform
    assert cov[em.index("j3.dy"), em.index("j3.dy")] == pytest.approx(0.2e-3**2 + 0.4e-3**2 / 12)
    assert budget.parameter_mean()[em.index("j3.dy")] == pytest.approx(0.1e-3)
    yaml_file = tmp_path / "budget.yaml"
    yaml_file.write_text("clearance:\n  axial_std_mm: 0.1\n  radial_std_um: 50\n  deflection_std_deg: 0.01\n")
    clearance = load_budget_file(yaml_file, tool_changer)
    assert clearance.radial_std == pytest.approx(50e-6)
    assert clearance.deflection_std == pytest.approx(np.radians(0.01))


@pytest.mark.parametrize("content, key", [
    ('[groups.drive]\ndistribution = "gamma"\nstd_deg = 1\n', "groups.drive.distribution"),
    ('[groups.link_length]\nstd_mm = -0.2\n', "groups.link_length.std_mm"),
    ('[parameters."j9.dx"]\nstd_mm = 0.2\n', "parameters.j9.dx"),
    ('[parameters."j2.dx"]\nstd_deg = 0.2\n', "parameters.j2.dx.std_deg"),
    ('[groups.elbow]\nstd_mm = 0.2\n', "groups.elbow"),
    ('[groups.link_length]\nstd_furlong = 0.2\n', "groups.link_length.std_furlong"),
    ('[parameters."j2.drive"]\ndistribution = "uniform"\nlow_deg = 1\nhigh_deg = -1\n', "parameters.j2.drive"),
    ('[clearance]\nradial_std_deg = 1\n', "clearance.radial_std_deg"),
    ('[groups.link_length\nstd_mm = 1\n', "not valid TOML"),
])
def test_bad_config_is_one_line_naming_file_and_key(tmp_path, capsys, content, key):
    path = tmp_path / "bad.toml"
    path.write_text(content)
    code, out, err = _run(capsys, ["--config", str(path), "--samples", "100", "--quiet"])
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and str(path) in err and key in err


@pytest.mark.parametrize("argv, fragment", [
    (["--tol", "0"], "--tol 0"),
    (["--tol", "0.15", "-1"], "--tol -1"),
    (["--angle-tol", "0"], "--angle-tol"),
    (["--samples", "1"], "--samples"),
    (["--workers", "0"], "--workers"),
    (["--q", "1", "2"], "--q"),
    (["--preset", "table9"], "invalid choice"),
])
def test_bad_arguments_exit_2_with_one_line(capsys, argv, fragment):
    code, out, err = _run_catching(capsys, argv)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and fragment in err


def _run_catching(capsys, argv):
    try:
        code = main(["montecarlo", "--quiet"] + argv)
    except SystemExit as exc:  # argparse usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err
