"""The .csr route of the kinematic calibration (vr_driver.csr.calibration, issue 25 item 2): taught
points from a program in joint form, rests found in the reported poses (stepped stamps, one thread),
each rest to its taught point by our model, the pairs YAML the fit reads -- and the refusals: a
Cartesian point, duplicates, an empty program, a rest that is no taught point, writing while points
are missing."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from vr_driver.csr import JointConvention, parse_program
from vr_driver.csr.calibration import PairRecorder, Rest, RestDetector, model_errors, taught_points
from vr_driver.errors import CsrError

from panasonic_vr006l_support import kinematic_calibration as kc

HEADER = "[Description]\nRobot, VR-006L\nComment, cal\nTool, 1:TOOL01\n\n[Pose]\n/Name, Type, RT, UA, FA, RW, BW, TW\n"


def program(poses, commands=""):
    return parse_program(HEADER + poses + "\n[Command]\nTOOL, 1:TOOL01\n" + commands, "cal.csr")


POSES = ("P001, AJ, 63.000, 59.000, -23.000, -153.000, -91.000, 27.000\n"
         "P002, AJ, -32.000, -83.000, -103.000, 96.000, -118.000, 69.000\n"
         "P003, AJ, 42.000, -85.000, 0.000, 10.000, -87.000, 62.000\n")


def test_taught_points_follow_the_moves_in_order_of_first_visit():
    prog = program(POSES, "MOVEP, P003, 5.00, m/min, N, -1\nMOVEP, P001, 5.00, m/min, N, -1\n"
                          "MOVEP, P003, 5.00, m/min, N, -1\n")
    points = taught_points(prog)
    assert [p.name for p in points] == ["P003", "P001"]            # P002 is never visited
    assert points[0].joints_deg == pytest.approx((42.0, -85.0, 0.0, 10.0, -87.0, 62.0))
    assert points[0].line == 10


def test_without_moves_every_pose_is_a_taught_point():
    assert [p.name for p in taught_points(program(POSES))] == ["P001", "P002", "P003"]


def test_the_convention_turns_aj_columns_into_the_models_joints():
    conv = JointConvention.from_options("horizontal", "UA", ["BW=-90"], coupling=1)
    p = taught_points(program(POSES), conv)[0]
    # AJ = sign * x + offset; FA counted from the horizontal: q3 = FA - coupling * q2
    q2 = -59.0
    assert p.joints_deg == pytest.approx((63.0, q2, -23.0 - q2, -153.0, -91.0 + 90.0, 27.0))
    assert conv.to_aj([math.radians(v) for v in p.joints_deg]) == pytest.approx(
        (63.0, 59.0, -23.0, -153.0, -91.0, 27.0))


def test_a_cartesian_point_is_refused_naming_it():
    prog = parse_program(HEADER.replace("RT, UA, FA, RW, BW, TW", "X, Y, Z, U, V, W")
                         + "P001, AU, 1000.0, 0.0, 800.0, 0.0, 90.0, 0.0\n\n[Command]\nTOOL, 1:TOOL01\n",
                         "cal.csr")
    with pytest.raises(CsrError, match="P001 is AU, not AJ.*joint form") as err:
        taught_points(prog, source="cal.csr")
    assert err.value.line == 8


def test_a_repeated_point_and_an_empty_program_are_refused():
    dup = POSES + "P004, AJ, 63.000, 59.000, -23.000, -153.000, -91.000, 27.010\n"
    with pytest.raises(CsrError, match="P004 repeats pose P001"):
        taught_points(program(dup))
    with pytest.raises(CsrError, match="no poses"):
        taught_points(program(""))


# ------------------------------------------------------------------------------- rest detector
def feed(det, start, end, pose, dt=0.05):
    out = []
    t = start
    while t <= end + 1e-9:
        r = det.feed(t, pose)
        if r is not None:
            out.append(r)
        t += dt
    return out


def test_a_rest_is_reported_once_after_the_hold_with_the_mean_pose():
    det = RestDetector(hold=1.0, still_mm=0.3, still_deg=0.05)
    base = np.array([1000.0, 10.0, 800.0, 179.99, 45.0, -30.0])
    rests = []
    for k in range(60):                                  # 3 s still, one-count flicker, Rx across +-180
        pose = base + [0.1 * (k % 2), 0.0, 0.0, -359.98 * (k % 2), 0.0, 0.0]     # 179.99 / -179.99
        r = det.feed(10.0 + 0.05 * k, pose)
        if r is not None:
            rests.append((10.0 + 0.05 * k, r))
    assert len(rests) == 1
    t, rest = rests[0]
    assert t == pytest.approx(11.0) and rest.start == pytest.approx(10.0) and rest.samples == 21
    assert rest.pose[0] == pytest.approx(1000.0 + 0.1 * 10 / 21)
    assert rest.pose[3] == pytest.approx(179.99 + 0.02 * 10 / 21)      # not the naive mean near 0
    assert rest.spread_mm == pytest.approx(0.1) and rest.spread_deg == pytest.approx(0.02)


def test_motion_a_gap_and_bad_samples_restart_the_rest():
    det = RestDetector(hold=1.0)
    pose = (1000.0, 0.0, 800.0, 0.0, 90.0, 0.0)
    assert feed(det, 0.0, 0.9, pose) == []
    moved = (1000.5, 0.0, 800.0, 0.0, 90.0, 0.0)          # 0.5 mm: moving again
    assert feed(det, 0.95, 1.8, moved) == []
    assert det.feed(1.85, (float("nan"),) * 6) is None and det.ignored == 1
    assert det.feed(1.9, (1.0, 2.0)) is None and det.ignored == 2
    assert det.feed(3.0, moved) is None                  # 1.15 s gap (a link loss): a new rest begins
    assert len(feed(det, 3.05, 4.1, moved)) == 1
    with pytest.raises(ValueError, match="hold must be a positive number"):
        RestDetector(hold=float("nan"))


# ------------------------------------------------------------------------------- pair recorder
@pytest.fixture(scope="module")
def errors():
    return model_errors()


def rest_at(pose, start=0.0):
    return Rest(start, start + 1.0, tuple(float(v) for v in pose), 20)


def test_each_rest_goes_to_its_point_and_the_yaml_is_what_fit_reads(errors, tmp_path):
    points = taught_points(program(POSES))
    truth = dict(kc.nominal_parameters(), upper_arm=kc.nominal_parameters()["upper_arm"] + 0.008)
    rec = PairRecorder(points, errors)
    home = kc.fk_controller(kc.nominal_parameters(), [0.0, 0.0, 0.0, 0.0, -90.0, 0.0])
    got, line = rec.add(rest_at(home))
    assert got is None and "matches no taught point" in line
    for p in reversed(points):
        got, line = rec.add(rest_at(kc.fk_controller(truth, list(p.joints_deg))))
        assert got is not None and got.point.name == p.name and "%s recorded" % p.name in line
        assert 0.5 < got.model_mm < 9.0
    assert rec.complete
    out = tmp_path / "pairs.yaml"
    rec.write(str(out), "cal.csr")
    pairs = kc.load_pairs(str(out))
    assert [tuple(j) for j, _ in pairs] == [pytest.approx(p.joints_deg, abs=1e-4) for p in points]
    assert pairs[1][1] == pytest.approx(list(kc.fk_controller(truth, list(points[1].joints_deg))), abs=1e-4)
    assert "taught points (joints): cal.csr" in out.read_text()


def test_a_later_rest_at_a_point_replaces_the_earlier(errors):
    points = taught_points(program(POSES))
    rec = PairRecorder(points, errors)
    pose = kc.fk_controller(kc.nominal_parameters(), list(points[0].joints_deg))
    rec.add(rest_at(pose, 0.0))
    got, line = rec.add(rest_at(pose + [0.5, 0, 0, 0, 0, 0], 5.0))
    assert "recorded again" in line and rec.recorded["P001"].rest.start == 5.0


def test_nothing_is_written_while_points_are_missing_unless_partial(errors, tmp_path):
    points = taught_points(program(POSES))
    rec = PairRecorder(points, errors)
    out = tmp_path / "pairs.yaml"
    with pytest.raises(CsrError, match="no taught point has a recorded pose"):
        rec.write(str(out))
    rec.add(rest_at(kc.fk_controller(kc.nominal_parameters(), list(points[1].joints_deg))))
    with pytest.raises(CsrError, match=r"2 of 3 taught points have no recorded pose \(P001, P003\)"):
        rec.write(str(out))
    assert not out.exists()
    text = rec.write(str(out), partial=True)
    assert "NOT RECORDED: P001, P003" in text and len(kc.load_pairs(str(out))) == 1
    with pytest.raises(CsrError, match="cannot write"):
        rec.write(os.path.join(str(tmp_path), "no", "such", "dir.yaml"), partial=True)
