"""Frames and ISO notes by hand (``frames/noise.py``, ``iso9283/evaluate.py``): the instrument's
scatter from reflectors on one rigid body with the pairs it may use chosen by the rules written out
here (not the same point, a nominal distance that holds within the tolerance), and the ISO
evaluation's note on a test too small for the unit check, word for word with its RMS spread from
Pinocchio. Each test names a planted change it was seen to catch (issue 36)."""

import json

import numpy as np
import pytest

from tcr_accuracy.frames.noise import noise_from_rigid_frames
from tcr_accuracy.model.robot import load_robot

from conftest import pinocchio_kinematics
from conftest import run_command as run


def test_rigid_frame_noise_pools_only_the_pairs_a_rigid_body_holds_apart():
    """Five reflectors over 12 rows: A at random places, B at A itself (the same point: no distance to
    watch), C = A + 100 mm x, D = A + (200 mm + delta) y with delta spanning 3 nm over the rows (not rigid:
    beyond the 1 nm + 1e-9 x distance tolerance), E = A + (50 mm + eps) z with eps spanning 0.9 nm (rigid
    within it); each measured with its own noise. The pairs kept: A-C, A-E, B-C, B-E, C-E; sigma = sqrt of
    the mean over them of var(measured distance, ddof 1) / 2. Seen failing on the same-point guard
    ``model.mean() <= 1e-6`` turned to ``<= -0.999999`` (A-B kept), the tolerance's ``1e-9 *
    model.mean()`` turned to ``1.000000001 *`` and ``tolerance: float = 1e-9`` to ``1.000000001``
    (A-D kept), and ``/ 2.0`` turned to ``/ 3.0``."""
    rng = np.random.default_rng(4)
    n = 12
    a = rng.uniform(-0.5, 0.5, (n, 3))
    delta = np.linspace(0.0, 3e-9, n)
    eps = np.linspace(0.0, 0.9e-9, n)
    nominal = [a, a.copy(), a + [0.1, 0.0, 0.0], a + np.outer(0.2 + delta, [0.0, 1.0, 0.0]),
               a + np.outer(0.05 + eps, [0.0, 0.0, 1.0])]
    measured = [p + rng.normal(0.0, 20e-6, p.shape) for p in nominal]
    got = noise_from_rigid_frames(nominal, measured, list("ABCDE"))
    kept = [(0, 2), (0, 4), (1, 2), (1, 4), (2, 4)]
    variances = [np.var(np.linalg.norm(measured[i] - measured[j], axis=1), ddof=1) / 2.0 for i, j in kept]
    assert got.per_axis == pytest.approx(np.sqrt(np.mean(variances)), rel=1e-12)
    assert got.detail == ("scatter of the distances between measured frames on one rigid body (A-C, A-E, B-C, B-E, "
                          "C-E; 12 rows): the instrument's own noise, whatever the robot does")
    assert got.source == "rigid frames" and got.independent



def test_rigid_frame_noise_needs_six_rows_and_two_frames():
    """Two reflectors 100 mm apart on one body: six rows give the estimate (sigma from the one pair, by hand),
    five rows or a single frame give none. Seen failing on ``min_rows: int = 6`` turned to 7 or 5 and
    ``len(nominal) < 2`` turned to ``< 3``."""
    rng = np.random.default_rng(9)
    a = rng.uniform(-0.5, 0.5, (6, 3))
    nominal = [a, a + [0.0, 0.1, 0.0]]
    measured = [p + rng.normal(0.0, 20e-6, p.shape) for p in nominal]
    got = noise_from_rigid_frames(nominal, measured, ["A", "B"])
    distance = np.linalg.norm(measured[0] - measured[1], axis=1)
    assert got.per_axis == pytest.approx(np.sqrt(np.var(distance, ddof=1) / 2.0), rel=1e-12)
    assert noise_from_rigid_frames([p[:5] for p in nominal], [p[:5] for p in measured], ["A", "B"]) is None
    assert noise_from_rigid_frames(nominal[:1], measured[:1], ["A"]) is None

def test_an_iso_test_too_small_for_the_unit_check_gives_its_spread_and_the_checks_need_in_mm(tmp_path, capsys):
    """Five UR10 poses within about a millimetre, four cycles, positions in mm: the note gives the RMS distance
    of the readings' nominal TCPs (Pinocchio's, at the poses' joints) from their centre in mm (3
    significant figures) and the check's need, 1 mm. Seen failing on ``MIN_UNIT_SPREAD * 1e3`` turned to
    ``+ 1e3`` and the spread's ``* 1e3`` changed."""
    robot = load_robot("ur10")
    rng = np.random.default_rng(8)
    poses = np.radians([20, -80, 100, -110, -90, 10]) + rng.uniform(-5e-4, 5e-4, (5, 6))
    head = ",".join(f"{n}_deg" for n in robot.joint_names) + ",x_mm,y_mm,z_mm,pose_id,cycle"
    lines, nominal = [head], []
    for cycle in range(1, 5):
        for k, q in enumerate(poses):
            tcp = pinocchio_kinematics(robot, q)[1].translation.copy()
            nominal.append(tcp)
            p = (tcp + rng.normal(0, 1e-6, 3)) * 1e3
            lines.append(",".join([*(repr(float(v)) for v in np.degrees(q)), *(repr(float(v)) for v in p),
                                   str(k + 1), str(cycle)]))
    path = tmp_path / "tiny.csv"
    path.write_text("\n".join(lines) + "\n")
    code, out, err = run(["iso9283", "evaluate", str(path), "--robot", "ur10", "--frame", "base", "--json", "-"],
                         capsys)
    assert code == 0, err
    nominal = np.array(nominal)
    spread = np.sqrt(np.mean(np.sum((nominal - nominal.mean(axis=0)) ** 2, axis=1)))
    assert 1e-4 < spread < 1e-3
    note = (f"the poses lie within {spread * 1e3:.3g} mm (RMS) of one another: too close for the measurement "
            "reader's unit check (it needs 1 mm), which did not run; make sure the position columns' unit is the "
            "file's")
    assert note in json.loads(out)["notes"]


def test_a_given_mpe_at_its_bounds_and_each_refusal_word_for_word():
    """An MPE a + b L: a up to 10 mm and b up to 1e-3 m/m taken, just beyond refused; a + b down to 1e-9 m taken,
    half of it refused; (0, 0) and a negative figure refused as not two numbers, not both 0 (the radial
    one named as such). Seen failing on ``values.sum() <= 0`` turned to ``<= -1`` (0, 0 refused by the
    range check instead), ``values < 0`` to ``< -1``, and ``MPE_MAX`` / ``MPE_MIN_M`` moved."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.frames.instrument import instrument_from

    for mpe in ((1e-2, 0.0), (0.0, 1e-3), (1e-9, 0.0), (0.5e-9, 0.5e-9)):
        assert instrument_from(mpe=mpe).transverse == mpe
    for pair in ((0.0, 0.0), (-0.5e-6, 1e-6)):
        with pytest.raises(InputError) as refused:
            instrument_from(mpe=pair)
        assert str(refused.value) == (f"instrument_mpe {list(pair)}: need two numbers a >= 0 [m] and b >= 0 [m/m], "
                                      "not both 0")
    for pair in ((1.0001e-2, 0.0), (0.0, 1.0001e-3), (0.5e-9, 0.0)):
        with pytest.raises(InputError) as refused:
            instrument_from(mpe=(1e-5, 1e-6), radial_mpe=pair)
        assert str(refused.value) == (f"instrument_radial_mpe {list(pair)}: want a <= 0.01 m and b <= 0.001 m/m, "
                                      "a + b >= 1e-09 (no measuring instrument lies outside)")
