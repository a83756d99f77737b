"""Every kind of plot reads at a glance (issue 21), measured on the drawn figure: tick labels
that stand apart (colour bars and 3D axes included), legends beside the data rather than over
it, text of at least 7 pt, category names written level, heat maps drawn to scale and filling
their axes, and PNGs without white margins. Each plot is drawn from small data made here;
the checks live in tests/readability.py."""

from types import SimpleNamespace

import numpy as np
import pytest

import readability as check
from tcr_accuracy.view import plots_diagnose, plots_montecarlo, plots_prediction, plots_sensitivity

#: long joint names, as URDFs of real robots have them
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]


@pytest.fixture
def figures(monkeypatch):
    from matplotlib import pyplot

    close = pyplot.close  # the capture keeps them open to be measured; closed here after the test
    with check.capture_figures(monkeypatch) as kept:
        yield kept
    for fig in kept:
        close(fig)


def assert_readable(fig, **kwargs):
    problems = check.readability_problems(fig, **kwargs)
    assert not problems, "\n".join(problems)


# ---------------------------------------------------------------------------------------
# the checks themselves catch what the issue showed
# ---------------------------------------------------------------------------------------
def test_the_checks_see_crowded_ticks_a_legend_on_data_and_tiny_text():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1.6, 1.6))
    ax.plot(np.linspace(-8000, 2000, 50), np.linspace(0, 1, 50), label="data")
    ax.set_xticks(np.arange(-8000, 2001, 1000))  # "-8000-7000-6000..." on 1.6 inches
    ax.legend(loc="center")
    ax.set_title("tiny", fontsize=5)
    assert check.overlapping_tick_labels(fig)
    assert check.legends_over_data(fig)
    assert check.small_texts(fig) == ["'tiny' at 5.0 pt"]
    plt.close(fig)


# ---------------------------------------------------------------------------------------
# Monte Carlo
# ---------------------------------------------------------------------------------------
def _monte_carlo(rng, n=4000):
    cloud = rng.normal(size=(n, 3)) * np.array([12.0, 1.5, 4.0]) * 1e-3  # [m], elongated along x
    cloud[:, 2] += 0.6 * cloud[:, 0]
    return SimpleNamespace(cloud=cloud, n_samples=20_000)


def test_error_cloud_3d_has_apart_ticks_and_fills_its_png(figures, tmp_path):
    plots_montecarlo.plot_cloud_3d(_monte_carlo(np.random.default_rng(0)), tmp_path / "cloud.png", title="table2")
    (fig,) = figures
    assert_readable(fig)
    ax = next(a for a in fig.axes if a.name == "3d")
    # equal scales: a cloud 8 times longer in x than in y looks it
    assert ax.get_xlim() == pytest.approx(ax.get_ylim())
    assert ax.get_xlim() == pytest.approx(ax.get_zlim())
    # the bulk fills the box: the limit is at most the 99.9 % quantile, not the farthest outlier
    cloud = _monte_carlo(np.random.default_rng(0)).cloud * 1e3
    assert ax.get_xlim()[1] <= np.quantile(np.abs(cloud).max(axis=1), 0.999) + 1e-9


def test_projection_heat_maps_are_to_scale_and_fill_their_axes(figures, tmp_path):
    result = _monte_carlo(np.random.default_rng(1))
    plots_montecarlo.plot_projection_densities(result, tmp_path / "density.png", title="table2")
    (fig,) = figures
    assert_readable(fig)
    maps = [ax for ax in fig.axes if ax.collections and ax.get_title().endswith("plane")]
    assert [ax.get_title() for ax in maps] == ["x-y plane", "x-z plane", "y-z plane"]
    cloud = result.cloud * 1e3
    for ax, (i, j) in zip(maps, ((0, 1), (0, 2), (1, 2))):
        box, data = check.display_aspect(ax)
        assert box == pytest.approx(data, rel=0.02)  # 1 mm as long on both axes
        assert 1 / 3 - 1e-9 <= data <= 3 + 1e-9  # an elongated cloud widened, not a sliver
        mesh = ax.collections[0].get_coordinates()  # the heat map covers the whole axes box
        assert (mesh[..., 0].min(), mesh[..., 0].max()) == pytest.approx(ax.get_xlim())
        assert (mesh[..., 1].min(), mesh[..., 1].max()) == pytest.approx(ax.get_ylim())
        # and every sample falls on it
        assert mesh[..., 0].min() <= cloud[:, i].min() and cloud[:, i].max() <= mesh[..., 0].max()
        assert mesh[..., 1].min() <= cloud[:, j].min() and cloud[:, j].max() <= mesh[..., 1].max()


# ---------------------------------------------------------------------------------------
# diagnosis
# ---------------------------------------------------------------------------------------
def _diagnosis(rng, n=240):
    steps = [SimpleNamespace(effect=e, heldout=SimpleNamespace(rms=r, mean=0.9 * r))
             for e, r in (("frames", 1.4e-3), ("compliance", 6e-4), ("joint_offsets", 3e-4), ("geometry", 2e-4),
                          ("backlash", 3.6e-5))]
    q = rng.uniform(-3, 3, (n, 6))
    residual = rng.normal(size=(n, 3)) * 1e-3
    lags = np.linspace(0.1, 3.3, 12)
    semis = [SimpleNamespace(lags=lags, semivariance=1 + 0.2 * rng.normal(size=(12, 3))) for _ in JOINTS]
    bins = [{"low": lo, "high": lo + 0.3, "mean_mm": list(rng.normal(size=3) * 0.01)} for lo in np.arange(0, 1.5, 0.3)]
    where_mm = {"octants": {"regions": [{"region": f"{a}x{b}y{c}z", "rms_mm": float(rng.uniform(0.1, 0.2))}
                                     for a in "-+" for b in "-+" for c in "-+"]},
             "radius": {"bins": bins}, "height": {"bins": bins}, "payload_kg": {"bins": bins},
             "temperature_c": {"bins": bins},
             "approach_direction": {j: {"difference_norm_mm": float(rng.uniform(0.003, 0.02))} for j in JOINTS}}
    angle = np.linspace(-np.pi, np.pi, 90)
    bands = {"cyclic": {j: {"angle_rad": angle, "value_rad": 2e-4 * np.sin(16 * angle),
                            "std_rad": np.full(90, 1e-5)} for j in JOINTS}}
    return SimpleNamespace(steps=steps, noise_floor=3.5e-5, gap_residual=residual, heldout_residual=0.03 * residual,
                           q=q, gravity_torque=np.c_[np.zeros(n), rng.uniform(-8000, 2000, (n, 2)),
                                                     rng.uniform(-3000, 3000, n), rng.uniform(-400, 400, (n, 2))],
                           semivariograms=semis, where_mm=where_mm, joint_function_bands=bands)


ROBOT = SimpleNamespace(joint_names=JOINTS, display_scale=np.full(6, 180 / np.pi), display_units=["deg"] * 6,
                        joint_kinds=["revolute"] * 6)


@pytest.mark.parametrize("kind", ["steps", "axes", "joints", "gravity", "semivariograms", "joint_functions"])
def test_diagnosis_plots_are_readable(kind, figures, tmp_path):
    d = _diagnosis(np.random.default_rng(2))
    draw = {"steps": lambda: plots_diagnose.plot_steps(d, tmp_path / "p.png"),
            "axes": lambda: plots_diagnose.plot_axes(d, tmp_path / "p.png"),
            "joints": lambda: plots_diagnose.plot_joints(d, ROBOT, tmp_path / "p.png"),
            "gravity": lambda: plots_diagnose.plot_gravity(d, ROBOT, tmp_path / "p.png"),
            "semivariograms": lambda: plots_diagnose.plot_semivariograms(d, ROBOT, tmp_path / "p.png"),
            "joint_functions": lambda: plots_diagnose.plot_joint_functions(d, "cyclic", tmp_path / "p.png")}
    draw[kind]()
    (fig,) = figures
    assert_readable(fig)


def test_gravity_torques_in_thousands_get_ticks_that_stand_apart(figures, tmp_path):
    """The user's "-5000-4000-3000": torques of -8000 to 2000 N m on a 3.4-inch panel."""
    plots_diagnose.plot_gravity(_diagnosis(np.random.default_rng(3)), ROBOT, tmp_path / "gravity.png")
    (fig,) = figures
    assert not check.overlapping_tick_labels(fig)
    panel = next(ax for ax in fig.axes if "shoulder_lift" in ax.get_xlabel())
    values = [float(t.get_text().replace("\u2212", "-")) for t in check._drawn_tick_labels(panel.xaxis)]
    assert len(values) >= 3 and min(values) <= -4000  # thinned, not emptied


def test_a_ladder_within_a_decade_labels_its_log_axis_apart(figures, tmp_path):
    """The real UR5's ladder, 0.63 mm down to 0.05 mm: matplotlib labels the minor ticks of a log axis
    spanning about a decade ("2x10^-1 3x10^-1 4x10^-1", run together); the labels stand apart, in plain
    numbers, and still mark both ends of the data."""
    effects = ["frames", "geometry", "transmission", "cyclic", "joint_offsets", "drift"]
    plots_diagnose.plot_ladder(effects, [0.70, 0.165, 0.10, 0.072, 0.060, 0.056],
                               [0.629, 0.148, 0.091, 0.063, 0.054, 0.051], 0.0368, tmp_path / "ladder.png")
    (fig,) = figures
    assert not check.overlapping_tick_labels(fig)
    values = [float(t.get_text().replace("\u2212", "-")) for t in check._drawn_tick_labels(fig.axes[0].xaxis)]
    assert len(values) >= 3 and min(values) <= 0.05 and max(values) >= 0.5


def test_region_names_are_level_and_large_enough(figures, tmp_path):
    plots_diagnose.plot_regions(_diagnosis(np.random.default_rng(4)), tmp_path / "regions.png")
    (fig,) = figures
    assert_readable(fig)
    octants = next(ax for ax in fig.axes if ax.get_title().startswith("octants"))
    approach = next(ax for ax in fig.axes if ax.get_title().startswith("approach"))
    for ax, names in ((octants, 8), (approach, len(JOINTS))):
        labels = check._drawn_tick_labels(ax.yaxis)
        assert len(labels) == names and not check.rotated_tick_labels(ax)
        assert min(lab.get_fontsize() for lab in labels) >= 8
    assert {lab.get_text() for lab in check._drawn_tick_labels(approach.yaxis)} == set(JOINTS)


# ---------------------------------------------------------------------------------------
# prediction and compensation
# ---------------------------------------------------------------------------------------
def test_a_hundred_predicted_poses_are_markers_not_spaghetti(figures, tmp_path):
    rng = np.random.default_rng(5)
    errors = rng.normal(size=(100, 3)) * 1e-3
    std = np.full((100, 3), 2e-5)
    measured = errors + rng.normal(size=(100, 3)) * 2e-5
    plots_prediction.plot_predicted_errors(errors, tmp_path / "pred.png", std=std, measured=measured)
    (fig,) = figures
    assert_readable(fig)
    for ax in fig.axes:
        for line in ax.get_lines():  # no line runs from one pose to the next
            joined = line.get_linestyle() not in ("None", "none", "", " ") and len(line.get_xdata()) > 2
            assert not joined, f"'{ax.get_title()}': a line joins {len(line.get_xdata())} poses"


def test_compensation_histogram_leads_with_what_compensation_leaves(figures, tmp_path):
    rng = np.random.default_rng(6)
    before, after = rng.uniform(0.5e-3, 4e-3, 40), rng.uniform(1e-9, 1e-6, 40)
    heldout = rng.uniform(0.01e-3, 0.06e-3, 40)
    plots_prediction.plot_compensation(before, after, tmp_path / "comp.png", heldout_miss=heldout)
    (fig,) = figures
    assert_readable(fig)
    texts = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
    assert texts[0].startswith("expected after compensation") and f"mean {heldout.mean() * 1e3:.2g} mm" in texts[0]
    assert texts[-1].startswith("the model's own miss") and "not a measurement" in texts[-1]
    assert f"{heldout.mean() * 1e3:.2g} mm" in fig.axes[0].get_title()


def test_prediction_semivariograms_and_similarity_are_readable(figures, tmp_path):
    rng = np.random.default_rng(7)
    q = rng.uniform(-1, 1, (80, 6))
    errors = np.c_[np.sin(q[:, 0]), np.cos(q[:, 1]), q[:, 2]] * 1e-4 + rng.normal(size=(80, 3)) * 1e-5
    plots_prediction.plot_semivariograms(q, errors, tmp_path / "semi.png", joint_names=JOINTS)
    dist = SimpleNamespace(joint=rng.uniform(0, 3, 300), cartesian=rng.uniform(0, 0.5, 300),
                           error=rng.uniform(0, 1e-3, 300))
    res = SimpleNamespace(pcc_joint=0.81, pcc_cartesian=0.42)
    plots_prediction.plot_similarity({"gravity": (dist, res), "geometry": (dist, res)}, tmp_path / "sim.png")
    for fig in figures:
        assert_readable(fig)


# ---------------------------------------------------------------------------------------
# sensitivity and trajectories
# ---------------------------------------------------------------------------------------
def test_sweep_sobol_and_trajectory_plots_are_readable(figures, tmp_path):
    rng = np.random.default_rng(8)
    sources = [f"{j} angle" for j in JOINTS]
    values = np.linspace(-1e-3, 1e-3, 9)
    errors = rng.normal(size=(6, 9, 8)) * 1e-4 + values[None, :, None] * rng.uniform(0.5, 2, (6, 1, 8))
    sweep = SimpleNamespace(source_names=sources, values=values, unit="rad",
                            output=lambda name: errors[:, :, plots_sensitivity.OUTPUTS.index(name)])
    plots_sensitivity.plot_sweep(sweep, plots_sensitivity.POSITION_OUTPUTS, "joint angle sweep", "angle [deg]",
                                 tmp_path / "sweep.png")
    s1 = rng.uniform(0, 0.5, (4, 6))
    sobol = SimpleNamespace(outputs=("dx", "dy", "dz", "norm"), source_names=sources, first_order=s1,
                            first_order_conf=0.05 + 0 * s1, total_order=s1 + 0.1, total_order_conf=0.05 + 0 * s1,
                            conf_level=0.95, n_base=512, ranking=lambda name: np.arange(6))
    plots_sensitivity.plot_sobol(sobol, tmp_path / "sobol.png")
    t = np.linspace(0, 4, 80)
    wave = np.c_[np.sin(t), np.cos(t), 0.5 * np.sin(2 * t)] * 1e-3
    bands = SimpleNamespace(trajectory=SimpleNamespace(time=t), quantiles=(0.025, 0.975), mean=wave,
                            lower=wave - 3e-4, upper=wave + 3e-4, first_order_std=np.full((80, 3), 1.4e-4),
                            n_samples=2000, source_names=sources,
                            contributions=np.abs(rng.normal(size=(80, 6, 3))) * 1e-4)
    plots_sensitivity.plot_trajectory_bands(bands, tmp_path / "bands.png")
    plots_sensitivity.plot_trajectory_contributions(bands, tmp_path / "contrib.png")
    assert len(figures) == 4
    for fig in figures:
        assert_readable(fig)


# ---------------------------------------------------------------------------------------
# The calibration report's plots, drawn from JSON results
# ---------------------------------------------------------------------------------------
def _iso_block(rng, load, compensated=True):
    poses = [{"pose": f"P{k}", "pose_id": k, "n": 30, "ap_mm": float(rng.uniform(0.05, 0.9)),
              "rp_mm": float(rng.uniform(0.02, 0.1))} for k in range(1, 6)]
    block = {"condition": {"load_pct": load, "speed_pct": 100.0}, "poses": poses}
    if compensated:
        block["compensated"] = {"poses": [{**p, "ap_mm": p["ap_mm"] / 5} for p in poses]}
    return block


@pytest.mark.parametrize("kind", ["families", "iso_one_condition", "iso_four_conditions", "changes"])
def test_report_plots_from_json_are_readable(kind, figures, tmp_path):
    from tcr_accuracy.view import plots_results

    rng = np.random.default_rng(4)
    families = [{"family": "gravity", "effects": ["compliance", "lateral_compliance"], "share_mm": 1.19,
                 "interval_mm": [0.69, 1.23]},
                {"family": "geometric", "effects": ["joint_offsets", "geometry"], "share_mm": 0.36,
                 "interval_mm": [0.23, 0.39]}]
    changes = [{"parameter": f"geometry.{j}.d{a}", "z": float(rng.uniform(0, 6)), "change": float(rng.normal()),
                "significant": False} for j in JOINTS for a in "xyz"]
    blocks = [_iso_block(rng, load) for load in (100.0, 100.0, 100.0, 10.0)]
    draw = {"families": lambda: plots_results.plot_families(families, tmp_path / "p.png"),
            "iso_one_condition": lambda: plots_results.plot_iso_poses({**blocks[0], "measurements": "iso.csv"},
                                                                      tmp_path / "p.png", {"ap": 0.25}),
            "iso_four_conditions": lambda: plots_results.plot_iso_poses(
                {**blocks[0], "conditions": blocks, "measurements": "iso.csv"}, tmp_path / "p.png",
                {"ap": 0.25, "rp": 0.05}),
            "changes": lambda: plots_results.plot_changes({"changes": changes, "z_threshold": 3.0, "old": "d100.json"},
                                                          tmp_path / "p.png")}
    draw[kind]()
    (fig,) = figures
    assert_readable(fig)
