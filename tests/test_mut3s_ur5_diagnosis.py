"""``diagnosis/stages/parameters.py``, ``result_json.py`` and ``result.py`` read whole (issue 36, third pass) on one
fast diagnosis: a UR5 (its tool frame is ``tool0``, not ``tool``) measured at a point 5 cm from ``tool0`` by a
tracker in a frame written out here, its joints 2-5 turned by hidden offsets (Pinocchio's forward kinematics;
the effects the diagnosis fits are not used to make the data). The fitted tracker frame, the as-built error
vector and the TCP-offset check are compared with that hidden truth and with the formulas written out; the
JSON form is read back and every view compared with the fitted one; the figures written only, and the views in
mm, against their metres times 1000. Each test names planted changes it was seen to catch."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.records import ErrorStats, Step
from tcr_accuracy.diagnosis.result import Diagnosis
from tcr_accuracy.diagnosis.result_json import STORED_VIEWS, diagnosis_document
from tcr_accuracy.io.measurement_set import MeasurementSet
from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.model.robot import load_robot

#: hidden joint offsets [rad] (joints 1 and 6 turn what the base and tool frames already hold: left at 0)
OFFSETS = np.array([0.0, 2e-3, -1.5e-3, 1e-3, 2.5e-3, 0.0])
#: the measured point in tool0's axes [m]
POINT = np.array([0.01, -0.02, 0.05])
#: the tool offset the user says [m] (1 mm off the hidden one along x)
GIVEN = np.array([0.011, -0.02, 0.05])
TRACKER = pin.SE3(Rotation.from_rotvec([0.05, -0.1, 0.8]).as_matrix(), np.array([2.0, -0.4, 0.3]))
NOISE_M = 5e-6
#: how far the reflector moved between two sessions [m]
RESEATED = np.array([0.003, 0.002, -0.004])


@pytest.fixture(scope="module")
def fitted():
    robot = load_robot("ur5")
    rng = np.random.default_rng(8)
    low, high = robot.joint_bounds()
    q = rng.uniform(np.maximum(low, -2.5), np.minimum(high, 2.5), (40, robot.n_joints))
    data = robot.model.createData()
    position = np.empty((40, 3))
    for i, row in enumerate(q + OFFSETS):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
        position[i] = TRACKER.act(data.oMf[robot.tool_frame_id].act(POINT))
    position += NOISE_M * rng.standard_normal(position.shape)
    measured = MeasurementSet(joint_names=robot.joint_names, q=q, position=position)
    estimator = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=5, stability_replays=2,
                             tcp_offset=GIVEN).fit(measured)
    return robot, estimator.result_


def test_the_tracker_frame_and_the_as_built_tool_offset_are_the_hidden_ones(fitted):
    """trackerMbase is the hidden tracker frame (to 30 um and 30 urad over a robot 1 m across, 5 um of
    noise); the as-built vector holds no base twist (exactly 0: it belongs to the tracker frame), its tool
    slice is the measured point's offset from tool0 (to 30 um) and its drive slice the hidden offsets of
    joints 2-5 (to 3e-5 rad). Seen failing on ``as_built[em.base_slice] = 0.0`` turned to ``1.0``, on
    ``homogeneous(*registered.stations[0]) @ pin.exp6(base_twist)`` losing the fitted twist (``base_twist *
    0``) and on ``theta = final["phi"] * final["scale"]`` turned to ``+`` (planted by hand)."""
    robot, d = fitted
    assert d.selected_effects == ["frames", "joint_offsets"] or list(d.selected_effects) == ["frames",
                                                                                              "joint_offsets"]
    np.testing.assert_allclose(d.trackerMbase[:3, :3], TRACKER.rotation, rtol=0, atol=3e-5)
    np.testing.assert_allclose(d.trackerMbase[:3, 3], TRACKER.translation, rtol=0, atol=3e-5)
    np.testing.assert_allclose(d.trackerMbase[3], [0.0, 0.0, 0.0, 1.0], rtol=0, atol=0)
    em = ErrorModel(robot)
    x = d.as_built_x
    assert np.all(x[em.base_slice] == 0.0)
    np.testing.assert_allclose(pin.exp6(x[em.tool_slice]).translation, POINT, rtol=0, atol=3e-5)
    np.testing.assert_allclose(x[em.drive_slice][1:5], OFFSETS[1:5], rtol=0, atol=3e-5)
    for name, value in d.parameters["joint_offsets"].items():
        j = robot.joint_names.index(name.split(".")[-1]) if name.split(".")[-1] in robot.joint_names else \
            int(name[-1]) - 1
        assert value == pytest.approx(OFFSETS[j], abs=3e-5), name


def test_the_tcp_offset_check_weighs_the_fitted_offsets_standard_errors_by_the_difference(fitted):
    """The given offset (1 mm off the hidden one along x) against the fitted one: their difference
    (fitted - given, mm in the detail) and its standard error, ``sqrt(sum((d_i / |d|)^2 s_i^2))`` with s_i the
    parameter table's standard errors of ``frames.tool.dx/dy/dz`` (written out): on a UR5, whose tool frame
    is ``tool0``, the TCP offset's parameters are still ``frames.tool.*`` (one measured frame). Seen failing
    on ``len(registered.parts) == 1`` turned to ``== 0`` and to ``== 2`` (planted by hand: the standard error
    is then 0, its names ``frames.tool0.*`` unknown)."""
    _, d = fitted
    check = next(c for c in d.stages.parameters.geometry_checks if c.what == "tcp_offset")
    fitted_mm = np.array(check.detail["fitted_mm"])
    np.testing.assert_allclose(fitted_mm, POINT * 1e3, rtol=0, atol=0.03)
    difference = fitted_mm * 1e-3 - GIVEN
    np.testing.assert_allclose(check.detail["difference_mm"], difference * 1e3, rtol=0, atol=1e-9)
    assert check.value == pytest.approx(np.linalg.norm(difference), rel=1e-9)
    std = d.parameter_table["frames"]["std"]
    sigma = np.array([std[f"frames.tool.{c}"] for c in ("dx", "dy", "dz")])
    assert np.all(sigma > 0) and np.all(np.isfinite(sigma))
    expected = math.sqrt(float(np.sum((difference / np.linalg.norm(difference)) ** 2 * sigma**2)))
    assert check.std == pytest.approx(expected, rel=1e-9)


def _same(fitted, read, where="") -> list:
    """Where two views differ beyond 1e-12 relative (floats), through dataclasses, dicts, lists and arrays."""
    if dataclasses.is_dataclass(fitted) and not isinstance(fitted, type):
        return _same(dataclasses.asdict(fitted), dataclasses.asdict(read), where)
    if isinstance(fitted, dict):
        if not isinstance(read, dict) or set(map(str, fitted)) != set(map(str, read)):
            return [f"{where}: keys {sorted(map(str, fitted))} against {sorted(map(str, read)) if isinstance(read, dict) else read}"]
        by_name = {str(k): v for k, v in read.items()}
        return [d for k, v in fitted.items() for d in _same(v, by_name[str(k)], f"{where}.{k}")]
    if isinstance(fitted, (list, tuple, np.ndarray)) and not (isinstance(fitted, np.ndarray) and fitted.ndim == 0):
        fitted, read = list(np.asarray(fitted, dtype=object)) if isinstance(fitted, np.ndarray) else list(fitted), \
            list(np.asarray(read, dtype=object)) if isinstance(read, np.ndarray) else list(read)
        if len(fitted) != len(read):
            return [f"{where}: {len(fitted)} items against {len(read)}"]
        return [d for k, (a, b) in enumerate(zip(fitted, read)) for d in _same(a, b, f"{where}[{k}]")]
    if isinstance(fitted, (bool, np.bool_)) or fitted is None or isinstance(fitted, str):
        return [] if fitted == read else [f"{where}: {fitted!r} against {read!r}"]
    if isinstance(fitted, (int, float, np.integer, np.floating)):
        a, b = float(fitted), float(read)
        if math.isinf(a) or math.isnan(a):
            return [] if (a == b or (math.isnan(a) and math.isnan(b))) else [f"{where}: {a} against {b}"]
        return [] if abs(a - b) <= 1e-12 * max(abs(a), abs(b)) + 1e-300 else [f"{where}: {a!r} against {b!r}"]
    return [] if fitted == read else [f"{where}: {fitted!r} against {read!r}"]


def test_every_view_read_back_from_the_json_form_is_the_fitted_one(fitted):
    """The diagnosis written as JSON text and read back (``Diagnosis.from_json``): every view the file holds
    (``STORED_VIEWS``) is the fitted diagnosis' view, each figure to 1e-12 relative (mm written, metres read
    back: a conversion wrong on either side shows); the figures written only (the final held-out RMS in mm
    and over the noise floor, the contributions) are the fitted ones in mm, written out. Seen failing on
    ``"noise_floor_mm": d.noise_floor * 1e3`` turned to ``* 1001.0``, on ``last.heldout.rms * 1e3`` turned to
    ``/ 1e3``, on ``v * 1e3`` (contribution) turned to ``** 1e3`` and on the reader's ``doc["train_rms_mm"] *
    1e-3`` turned to ``* 0.001001`` (planted by hand)."""
    _, d = fitted
    doc = json.loads(json.dumps(d.to_dict()))
    read = Diagnosis.from_json(json.dumps(doc))
    assert read.from_file and not d.from_file
    views = [name for name in STORED_VIEWS if isinstance(getattr(Diagnosis, name, None), property)]
    # read by other readers than the views: export's parameter names, the report's point set, the joints
    assert set(STORED_VIEWS) - set(views) == {"effect_parameter_names", "measured_points", "joint_names"}
    assert read.joint_names == d.joint_names == list(fitted[0].joint_names)
    differences = {name: _same(getattr(d, name), getattr(read, name), name) for name in views}
    assert {name: found for name, found in differences.items() if found} == {}
    last = d.steps[-1].heldout.rms
    assert doc["final_heldout_rms_mm"] == pytest.approx(last * 1e3, rel=1e-12)
    assert doc["final_over_noise"] == pytest.approx(last / d.noise_floor, rel=1e-12)
    assert doc["noise_floor_mm"] == pytest.approx(d.noise_floor * 1e3, rel=1e-12)
    assert doc["tracker_noise_mm"] == pytest.approx(d.noise.per_axis * 1e3, rel=1e-12)
    assert doc["contribution_mm"] == pytest.approx({e: v * 1e3 for e, v in d.contribution.items()}, rel=1e-12)
    assert doc["n_measurements"] == 40 and doc["tool_frame"] == "tool0"
    assert "frames_measured" not in doc and "heldout_by_frame" not in doc


def test_the_final_figures_written_are_the_last_steps_of_a_longer_shrink_table(fitted):
    """The same diagnosis with a third step added to its shrink table (written here, 0.125 mm held-out RMS):
    the final held-out RMS written is that step's, in mm, and over the noise floor; with a noise floor of 0
    the ratio is null. Seen failing on ``last = d.steps[-1]`` turned to ``d.steps[1]`` (the second step, the
    last of a two-step table) and on ``if d.noise_floor > 0`` turned to ``> 1`` (planted by hand)."""
    _, d = fitted
    extra = Step("drift", ("frames", "joint_offsets", "drift"), 15, 1e-4, ErrorStats(1e-4, 1.25e-4, 3e-4, 40), 4.0)
    attribute = dataclasses.replace(d.stages.attribute, steps=tuple(d.stages.attribute.steps) + (extra,))
    longer = dataclasses.replace(d, stages=dataclasses.replace(d.stages, attribute=attribute))
    doc = diagnosis_document(longer)
    assert doc["final_heldout_rms_mm"] == pytest.approx(0.125, rel=1e-12)
    assert doc["final_over_noise"] == pytest.approx(1.25e-4 / d.noise_floor, rel=1e-12)
    assert 0 < d.noise_floor < 1
    residual = dataclasses.replace(d.stages.residual, noise=dataclasses.replace(d.stages.residual.noise,
                                                                               per_axis=0.0))
    silent = dataclasses.replace(d, stages=dataclasses.replace(d.stages, residual=residual))
    assert diagnosis_document(silent)["final_over_noise"] is None


def test_the_fitted_views_in_mm_the_summary_line_and_the_tracker_positions(fitted):
    """The leave-one-out rows carry stage 4's own share of each effect and its interval in mm (its metres times
    1000); the one-line repr gives the gap, the final held-out RMS and the noise floor in mm to four digits;
    the model's tracker positions at fresh poses are the hidden robot's (its point through the tracker frame,
    Pinocchio here) to 30 um. Seen failing on ``own[r.effect][0] * 1e3`` turned to ``* 1001.0``, on ``own[r.effect][2]
    * 1e3`` turned to ``own[r.effect][1]``, on the repr's ``self.noise_floor * 1e3`` turned to ``/ 1e3`` and on
    ``vector[...] = 0.0`` (the base twist left to trackerMbase) turned to ``1.0`` (planted by hand)."""
    robot, d = fitted
    own = d.stages.attribute.own_shares
    rows = {row["dropped"]: row for row in d.leave_one_out}
    assert set(rows) == {"joint_offsets"} and set(own) >= {"joint_offsets"}
    share, low, high = own["joint_offsets"]
    assert low < share < high
    assert rows["joint_offsets"]["own_share_increase_mm"] == pytest.approx(share * 1e3, rel=1e-12)
    assert rows["joint_offsets"]["own_share_interval_mm"] == pytest.approx([low * 1e3, high * 1e3], rel=1e-12)
    assert repr(d) == (f"Diagnosis('ur5', 40 measurements, gap RMS {d.gap.rms * 1e3:.4g} mm, selected [frames, "
                       f"joint_offsets], primary 'joint_offsets', held-out RMS {d.steps[-1].heldout.rms * 1e3:.4g} mm, "
                       f"noise floor {d.noise_floor * 1e3:.4g} mm)")
    q = np.random.default_rng(9).uniform(-2.0, 2.0, (10, robot.n_joints))
    data = robot.model.createData()
    truth = np.empty((10, 3))
    for i, row in enumerate(q + OFFSETS):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
        truth[i] = TRACKER.act(data.oMf[robot.tool_frame_id].act(POINT))
    np.testing.assert_allclose(d.tracker_positions(robot, q), truth, rtol=0, atol=3e-5)


@pytest.fixture(scope="module")
def reseated():
    """The same UR5 measured in two sessions whose rows alternate (A, B, A, B, ...), the reflector re-seated
    3.0, 2.0, -4.0 mm further in session B (the tracker not moved)."""
    robot = load_robot("ur5")
    rng = np.random.default_rng(8)
    low, high = robot.joint_bounds()
    q = rng.uniform(np.maximum(low, -2.5), np.minimum(high, 2.5), (40, robot.n_joints))
    session = np.array(["A", "B"] * 20)
    data = robot.model.createData()
    position = np.empty((40, 3))
    for i, row in enumerate(q + OFFSETS):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
        position[i] = TRACKER.act(data.oMf[robot.tool_frame_id].act(POINT + (RESEATED if session[i] == "B" else 0.0)))
    position += NOISE_M * rng.standard_normal(position.shape)
    measured = MeasurementSet(joint_names=robot.joint_names, q=q, position=position, session=session)
    return robot, GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=5, stability_replays=2).fit(measured).result_


def test_the_as_built_tool_is_the_first_rows_session_and_the_second_sessions_offset_its_own(reseated):
    """A TCP offset per session is chosen; the as-built tool slice is the offset of the first row's session (A:
    the hidden point, to 30 um), not B's, 5.4 mm away; B's own offset against A in the session sizes is the
    re-seat, in mm, to 0.03 mm. Seen failing on ``b.per_part[0].basis.errors(full, rows=[0])`` turned to
    ``rows=[1]`` and to ``rows=[-1]`` (planted by hand: the rows alternate, so row 1 and the last row are B's)."""
    robot, d = reseated
    assert d.session_setup["chosen"] == "tool offset per session"
    tool = pin.exp6(d.as_built_x[ErrorModel(robot).tool_slice]).translation
    np.testing.assert_allclose(tool, POINT, rtol=0, atol=3e-5)
    (b,) = d.session_setup["sessions"]
    assert (b["session"], b["against"]) == ("B", "A")
    np.testing.assert_allclose(b["tool_offset_mm"], RESEATED * 1e3, rtol=0, atol=0.03)


def test_a_document_without_its_counts_reads_them_as_none_counted(fitted):
    """The JSON form read back keeps its counts (40 rows, 5 folds, the fits run); a document without
    ``n_measurements``, ``folds`` and ``n_fits`` (written by an older version) reads them as 0, not as some
    default count, and one without ``joint_names`` nor ``where`` has no joint names. Seen failing on
    ``document.get("n_measurements", 0)`` turned to ``1`` (a measuring sample's survivor, seed 4202: budget
    spent), on ``document.get("folds", 0)`` turned to ``1`` and on ``int(n_fits) if n_fits else 0`` turned to
    ``else 1`` (planted by hand)."""
    _, d = fitted
    doc = json.loads(json.dumps(d.to_dict()))
    read = Diagnosis.from_dict(doc)
    assert (read.n_measurements, read.folds, read.n_fits) == (40, 5, d.n_fits) and d.n_fits > 0
    for key in ("n_measurements", "folds", "n_fits", "joint_names", "where"):
        del doc[key]
    old = Diagnosis.from_dict(doc)
    assert (old.n_measurements, old.folds, old.n_fits, old.joint_names) == (0, 0, 0, [])
